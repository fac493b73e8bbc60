//! Neural networks on tch: MLP blocks, the Gaussian actor-critic, the T-REX reward net and
//! ensembles, and a pure-Rust copy of an MLP for per-step inference in rollouts (one
//! observation at a time, where libtorch's per-call overhead would dominate).
pub mod cpu;
pub mod mlp;
pub mod policy;
pub mod reward;
pub mod sidecar;

pub use cpu::MlpCpu;
pub use mlp::{Activation, Init, Mlp};
pub use policy::{ActorCritic, PolicyConfig};
pub use reward::{RewardConfig, RewardEnsemble, RewardNet};

/// Runs `f` (which builds networks) with libtorch's global generator seeded to `seed`,
/// holding a process-wide lock: stages run in parallel threads, and without the lock their
/// initialisations would interleave on the one global generator and stop being
/// reproducible. Everything random after initialisation uses our own seeded generators.
pub fn seeded<T>(seed: u64, f: impl FnOnce() -> T) -> T {
    static INIT: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _guard = INIT.lock().unwrap_or_else(|e| e.into_inner());
    tch::manual_seed(seed as i64);
    f()
}
