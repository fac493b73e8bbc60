//! The Python baselines the benchmarks run, compiled into the binary: a build made in any
//! clone (one since deleted among them, such as the clones test's) runs the scripts of the
//! sources it was built from, and needs no path into a clone at run time.
use std::process::{Command, Output};

use anyhow::Context;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Script {
    /// Gymnasium's Python environment stepped with random actions (`bench env`).
    GymBench,
    /// EnvPool's environments, one and in batches (`bench env --envpool`).
    EnvpoolBench,
    /// Stable-Baselines3's PPO at CleanRL's settings (`bench ppo`).
    BenchPpo,
    /// The T-REX and BC loops in PyTorch (`bench learners`).
    BenchLearners,
}

impl Script {
    pub fn file_name(self) -> &'static str {
        match self {
            Script::GymBench => "gym_bench.py",
            Script::EnvpoolBench => "envpool_bench.py",
            Script::BenchPpo => "bench_ppo.py",
            Script::BenchLearners => "bench_learners.py",
        }
    }

    fn text(self) -> &'static str {
        match self {
            Script::GymBench => include_str!("../../analysis/gym_bench.py"),
            Script::EnvpoolBench => include_str!("../../analysis/envpool_bench.py"),
            Script::BenchPpo => include_str!("../../analysis/bench_ppo.py"),
            Script::BenchLearners => include_str!("../../analysis/bench_learners.py"),
        }
    }

    /// Runs the script with `python` and `args`, from a private temporary copy that is
    /// removed afterwards; fails with the script's name and its standard error.
    pub fn run(self, python: &str, args: &[String]) -> anyhow::Result<Output> {
        let dir = std::env::temp_dir().join(format!("idrex-script-{}-{}", std::process::id(), self.file_name()));
        std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let path = dir.join(self.file_name());
        std::fs::write(&path, self.text()).with_context(|| format!("cannot write {}", path.display()))?;
        let out = Command::new(python).arg(&path).args(args).output();
        let _ = std::fs::remove_dir_all(&dir);
        let out = out.with_context(|| format!("cannot run {python} {}", self.file_name()))?;
        anyhow::ensure!(out.status.success(), "analysis/{} failed: {}", self.file_name(), String::from_utf8_lossy(&out.stderr));
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The compiled-in texts are the scripts' (no path into the clone is kept).
    #[test]
    fn every_script_is_compiled_in() {
        for s in [Script::GymBench, Script::EnvpoolBench, Script::BenchPpo, Script::BenchLearners] {
            assert!(s.text().contains("import argparse") && s.text().len() > 500, "{}", s.file_name());
        }
        let e = Script::GymBench.run("/nonexistent/python", &[]).unwrap_err().to_string();
        assert!(e.contains("gym_bench.py"), "{e}");
    }
}
