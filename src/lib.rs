//! idrex: reward learning from automatically ranked demonstrations (D-REX, iD-REX).
//!
//! Data flow (each stage's parameters, metrics and body in `pipeline::stage::<kind>`, its
//! algorithm under `algo`):
//!
//! ```text
//! env ──> demos ──> bc ──> noise rollouts ──> trex ──> ppo ──> evaluation rollouts
//!                                   ^                                  │
//!                                   └──────── iD-REX iterations ───────┘
//! ```
//!
//! Unsafe code is denied except where it is named: the SIMD kernels (`kernels`, the whole
//! module, and the passes its `vectorised!` macro compiles twice), the vectorised environments' worker pool (`env::vec_env`), MuJoCo's actuator
//! ranges (`env::Env::with_model`) and logging hook (`cli::init_tracing`), the atomic
//! directory exchange (`store::exchange`) and loading libtorch's CUDA backend
//! (`nn::device`).
#![deny(unsafe_code)]
pub mod algo;
pub mod bench;
pub mod cli;
pub mod data;
pub mod env;
pub mod error;
pub mod exp;
#[allow(unsafe_code)] // intrinsics behind runtime feature checks, and aligned buffers
pub mod kernels;
pub mod log;
pub mod nn;
pub mod pipeline;
pub mod report;
pub mod rollout;
pub mod seed;
pub mod stats;
pub mod store;

pub use error::{Error, Result};

/// This build's version with the commit it was built from (`0.1.0+3f08a66c1d2e`; `.dirty`
/// when its sources differed from that commit), as manifests record it.
pub const VERSION: &str = concat!(env!("CARGO_PKG_VERSION"), env!("IDREX_BUILD_COMMIT"));
