//! `idrex bench`: every benchmark is a ratio against a baseline measured in the same run.
pub mod clones;
pub mod env;
pub mod exp;
pub mod learners;
pub mod ppo;
pub mod scripts;
pub mod trex;

pub use env::{EnvBench, EnvBenchArgs, default_python, env_bench, measure_env};
pub use learners::{LearnersBenchArgs, learners_bench};
pub use ppo::{PpoBenchArgs, ppo_bench};
pub use trex::{TrexBenchArgs, trex_bench};
