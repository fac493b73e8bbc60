//! The learning algorithms: behavioural cloning, noise injection, T-REX and PPO, and the
//! scoring and selection that evaluation and multi-BC decide with.
pub mod bank;
pub mod bc;
pub mod noise;
pub mod ppo;
pub mod scoring;
pub mod trex;
