//! What idrex writes for people and outside tools besides the rollouts (whose MCAP format
//! lives with them, in [`crate::rollout`]): plots as Rerun recordings, progress, and the one
//! writer of every table.
pub mod progress;
pub mod rerun;
pub mod table;
