//! Where an episode ends ([`Horizon`]).
use super::EnvId;

/// Where an episode ends: at the task's own termination (Gymnasium's default), or only at the
/// time limit (Gymnasium's `terminate_when_unhealthy=False`: an unhealthy robot keeps
/// stepping, without the healthy reward). A fixed horizon keeps a reward learned from ranked
/// rollouts from satisfying the ranking by paying for survival alone (SSRR runs its ranked
/// rollouts this way on Hopper and Ant). Evaluations always use the task's own.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Horizon {
    /// The task's termination (a task without one, HalfCheetah, runs to the time limit).
    #[default]
    Task,
    /// Every episode runs to the time limit.
    Fixed,
}

impl Horizon {
    pub fn is_task(&self) -> bool {
        *self == Horizon::Task
    }

    /// This horizon on `env`: on a task that never ends early (HalfCheetah) `fixed` changes
    /// nothing, and is `task` there so that keys stay the same.
    pub fn on(self, env: EnvId) -> Horizon {
        if env.spec().health.is_none() { Horizon::Task } else { self }
    }
}
