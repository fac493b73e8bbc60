//! The learning algorithms: behavioural cloning, noise injection, T-REX and PPO.
pub mod bc;
pub mod noise;
pub mod ppo;
pub mod trex;
