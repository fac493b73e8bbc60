//! `bc`: behavioural cloning of the demonstrations ([`crate::algo::bc`]).
use std::path::PathBuf;

use super::{POLICY, StageCtx, read_rollouts};
use crate::algo::bc::{self, BcConfig, BcReport};
use crate::env::EnvId;
use crate::error::Result;
use crate::nn::Device;

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BcParams {
    pub env: EnvId,
    pub bc: BcConfig,
    /// Where it computes; absent (the CPU) from a CPU stage's parameters, and so its key.
    #[serde(default, skip_serializing_if = "Device::is_cpu")]
    pub device: Device,
}

crate::stage_inputs! {
    /// BC reads the demonstrations.
    BcInputs { demos: One Demos }
}

pub fn run(p: &BcParams, inputs: &BcInputs<PathBuf>, ctx: &StageCtx) -> Result<BcReport> {
    let trajs = read_rollouts(&inputs.demos)?;
    ctx.progress.set_message("behavioural cloning");
    let (mut policy, report) = bc::train(&trajs, &p.bc, ctx.seed, ctx.threads, p.device)?;
    policy.env = Some(p.env.name().to_string());
    policy.save(&ctx.out.join(POLICY), serde_json::to_value(&p.bc).unwrap_or_default())?;
    Ok(report)
}
