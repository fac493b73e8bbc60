//! The roles in which a stage reads its inputs. A role's name is part of every key that uses
//! it, so names never change; code names a role by [`Role`], and the name is written only at
//! the boundary (keys, manifests, Slurm definitions) and read back with [`Role::parse`].

/// The key of a stored artifact's input in `role`, read from its manifest: the one place
/// outside the stages' own parsing ([`crate::pipeline::stage::Inputs::from_recorded`]) where a
/// recorded role name is read (the report's lineage queries and the test-set check go
/// through it).
pub fn recorded_input(m: &crate::store::Manifest, role: Role) -> Option<&String> {
    m.inputs.get(&role.name())
}

/// The keys of a stored artifact's inputs in `series` (a reward's ranked sets), in the
/// manifest's order.
pub fn recorded_series(m: &crate::store::Manifest, series: Series) -> impl Iterator<Item = &String> {
    m.inputs.iter().filter(move |(name, _)| Role::named_in(name, series)).map(|(_, k)| k)
}

/// What a stage reads an input as.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Role {
    /// The policy a stage rolls out or evaluates.
    Policy,
    /// The demonstrations.
    Demos,
    /// The learned reward (for multi-BC, the previous iteration's).
    Reward,
    /// D-REX's ranked set, on which PPO measures the ranked floor and the ceiling.
    Floor,
    /// Multi-BC's held-out reward, trained on the previous iteration's rankings.
    Judge,
    /// The reward bench: PPO's checkpoints on the task's reward, and on its backward twin.
    Forward,
    Backward,
    /// The reward bench's bank of gaits.
    Bank,
    /// The i-th input of a series.
    Nth(Series, usize),
}

/// Inputs a stage reads as a numbered series (`set0`, `set1`, ...).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Series {
    /// iD-REX: the current iteration's policies.
    Policy,
    /// Interpolation: the previous iteration's policies, paired with `Policy`.
    Older,
    /// T-REX: the ranked sets.
    Set,
    /// Multi-BC: the previous iteration's ranked sets, the filter's baselines.
    Baseline,
    /// Multi-BC: the source runs' evaluations.
    Eval,
}

impl Series {
    const ALL: [Series; 5] = [Series::Policy, Series::Older, Series::Set, Series::Baseline, Series::Eval];

    fn prefix(self) -> &'static str {
        match self {
            Series::Policy => "policy",
            Series::Older => "older",
            Series::Set => "set",
            Series::Baseline => "baseline",
            Series::Eval => "eval",
        }
    }

    /// The series' `i`-th role.
    pub fn at(self, i: usize) -> Role {
        Role::Nth(self, i)
    }
}

impl Role {
    const SINGLE: [Role; 8] =
        [Role::Policy, Role::Demos, Role::Reward, Role::Floor, Role::Judge, Role::Forward, Role::Backward, Role::Bank];

    /// The name keys and manifests record.
    pub fn name(self) -> String {
        match self {
            Role::Policy => "policy".into(),
            Role::Demos => "demos".into(),
            Role::Reward => "reward".into(),
            Role::Floor => "floor".into(),
            Role::Judge => "judge".into(),
            Role::Forward => "forward".into(),
            Role::Backward => "backward".into(),
            Role::Bank => "bank".into(),
            Role::Nth(s, i) => format!("{}{i}", s.prefix()),
        }
    }

    /// The series the role belongs to, if numbered.
    pub fn series(self) -> Option<Series> {
        match self {
            Role::Nth(s, _) => Some(s),
            _ => None,
        }
    }

    /// Whether a recorded name is a role of `series` (how the report reads manifests).
    pub fn named_in(name: &str, series: Series) -> bool {
        Role::parse(name).and_then(Role::series) == Some(series)
    }

    /// The role a recorded name of `what` (a node, an artifact) stands for, or the error
    /// that names it.
    pub fn recorded(name: &str, what: &str) -> crate::error::Result<Role> {
        Role::parse(name).ok_or_else(|| crate::error::Error::Invalid(format!("{what}: no stage reads an input as '{name}'")))
    }

    /// The role a recorded name stands for (the inverse of [`Role::name`]).
    pub fn parse(name: &str) -> Option<Role> {
        if let Some(r) = Role::SINGLE.into_iter().find(|r| r.name() == name) {
            return Some(r);
        }
        Series::ALL.into_iter().find_map(|s| {
            let digits = name.strip_prefix(s.prefix())?;
            // Canonical numbers only ("set01" is no role), so that names and roles are one-to-one.
            let i: usize = digits.parse().ok().filter(|i: &usize| i.to_string() == digits)?;
            Some(Role::Nth(s, i))
        })
    }
}

impl std::fmt::Display for Role {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_the_recorded_ones_and_parse_back() {
        let names = ["policy", "demos", "reward", "floor", "judge", "policy0", "older1", "set0", "baseline2", "eval11"];
        for name in names {
            let role = Role::parse(name).unwrap_or_else(|| panic!("{name}"));
            assert_eq!(role.name(), name);
        }
        assert_eq!(Role::parse("set12"), Some(Series::Set.at(12)));
        assert_eq!(Role::parse("policy"), Some(Role::Policy));
        for bad in ["", "set", "set01", "sets1", "Policy", "judge0", "set-1", "in0"] {
            assert_eq!(Role::parse(bad), None, "{bad}");
        }
    }
}
