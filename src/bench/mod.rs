//! `idrex bench`: every benchmark is a ratio against a baseline measured in the same run.
pub mod clones;
pub mod env;
pub mod envpool;
pub mod exp;
pub mod learners;
pub mod ppo;
pub mod scripts;
pub mod trex;

pub use env::{EnvBench, EnvBenchArgs, default_python, measure_env};
pub use learners::{LearnersBenchArgs, learners_bench};
pub use ppo::{PpoBenchArgs, ppo_bench};
pub use trex::{TrexBenchArgs, trex_bench};

/// `idrex bench env`: idrex's environments against mj_step and Gymnasium, then, with
/// `--envpool`, against EnvPool.
pub fn env_bench(args: &EnvBenchArgs) -> anyhow::Result<()> {
    env::table(args)?;
    match &args.envpool {
        Some(python) => envpool::run(python, args),
        None => Ok(()),
    }
}
