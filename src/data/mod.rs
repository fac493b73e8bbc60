//! Trajectories and the statistics shared between stages.
pub mod normalize;
pub mod npz;
pub mod trajectory;

pub use normalize::RunningMeanStd;
pub use trajectory::{TrajMeta, Trajectory};
