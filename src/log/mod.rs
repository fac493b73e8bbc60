//! What idrex writes for outside tools: trajectories as MCAP (the rollout artifacts
//! themselves) and flat CSV/NDJSON exports of them, plots as Rerun recordings.
pub mod export;
pub mod mcap;
pub mod progress;
pub mod rerun;
pub mod table;
