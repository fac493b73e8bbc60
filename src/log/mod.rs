//! What idrex writes for outside tools: trajectories as MCAP (the rollout artifacts
//! themselves), plots as Rerun recordings.
pub mod mcap;
pub mod rerun;
