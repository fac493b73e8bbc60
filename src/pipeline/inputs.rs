//! What a stage reads, declared per stage kind as a struct ([`crate::stage_inputs!`]): the graph
//! fills it with node names, the runner resolves it to artifact directories, and a stage's
//! body gets its own kind's struct. Roles ([`Role`]) appear only where inputs cross a
//! boundary (keys, manifests, Slurm definitions): [`StageInputs::roles`] writes them in one
//! place and [`Named`] reads them back, refusing a missing, repeated or unknown one.
use std::collections::BTreeMap;

use super::role::{Role, Series};
use crate::error::{Error, Result};

/// One kind's inputs: `T` is a node's name in a graph, an artifact's key, or its directory.
pub trait StageInputs<T>: Sized {
    /// (role, input) in the fields' order, a series' inputs in order.
    fn roles(&self) -> Vec<(Role, &T)>;
    /// Takes the kind's inputs out of `named`.
    fn take(named: &mut Named<T>) -> Result<Self>;
}

/// Inputs by role, as recorded; taken out one by one, and whatever is left is an error.
pub struct Named<T> {
    node: String,
    by_role: BTreeMap<Role, T>,
}

impl<T> Named<T> {
    /// `node` names the node in messages.
    pub fn new(node: &str, inputs: impl IntoIterator<Item = (Role, T)>) -> Result<Self> {
        let mut by_role = BTreeMap::new();
        for (role, t) in inputs {
            if by_role.insert(role, t).is_some() {
                return Err(Error::Invalid(format!("node {node}: input '{role}' is given twice")));
            }
        }
        Ok(Named { node: node.to_string(), by_role })
    }

    pub fn one(&mut self, role: Role) -> Result<T> {
        self.by_role.remove(&role).ok_or_else(|| Error::Invalid(format!("node {}: its input '{role}' is missing", self.node)))
    }

    pub fn maybe(&mut self, role: Role) -> Option<T> {
        self.by_role.remove(&role)
    }

    /// The series' inputs `0, 1, ...` up to the first gap.
    pub fn many(&mut self, series: Series) -> Vec<T> {
        (0..).map_while(|i| self.by_role.remove(&series.at(i))).collect()
    }

    /// Fails on any input the kind does not read.
    pub fn finish(self, kind: &str) -> Result<()> {
        match self.by_role.keys().next() {
            None => Ok(()),
            Some(role) => Err(Error::Invalid(format!("node {}: a {kind} stage reads no input '{role}'", self.node))),
        }
    }
}

/// A kind's input read once, perhaps, or as a series (the field types [`crate::stage_inputs!`]
/// writes).
pub type One<T> = T;
pub type Maybe<T> = Option<T>;
pub type Many<T> = Vec<T>;

/// Declares a kind's inputs: each field is `One ROLE`, `Maybe ROLE` (a [`Role`]) or
/// `Many SERIES` (a [`Series`]).
#[macro_export]
macro_rules! stage_inputs {
    ($(#[$m:meta])* $name:ident { $($(#[$fm:meta])* $field:ident: $card:ident $role:ident),* $(,)? }) => {
        $(#[$m])*
        #[derive(Debug, Clone, PartialEq)]
        pub struct $name<T> {
            $($(#[$fm])* pub $field: $crate::pipeline::inputs::$card<T>,)*
        }

        impl<T> $crate::pipeline::inputs::StageInputs<T> for $name<T> {
            // A kind's roles are pushed one macro arm each.
            #[allow(clippy::vec_init_then_push)]
            fn roles(&self) -> Vec<($crate::pipeline::role::Role, &T)> {
                #[allow(unused_mut)]
                let mut out = Vec::new();
                $($crate::stage_inputs!(@roles $card $role, &self.$field, out);)*
                out
            }

            fn take(named: &mut $crate::pipeline::inputs::Named<T>) -> $crate::error::Result<Self> {
                Ok($name { $($field: $crate::stage_inputs!(@take $card $role, named),)* })
            }
        }
    };
    (@roles One $role:ident, $f:expr, $out:ident) => { $out.push(($crate::pipeline::role::Role::$role, $f)) };
    (@roles Maybe $role:ident, $f:expr, $out:ident) => { $out.extend($f.iter().map(|x| ($crate::pipeline::role::Role::$role, x))) };
    (@roles Many $role:ident, $f:expr, $out:ident) => {
        $out.extend($f.iter().enumerate().map(|(i, x)| ($crate::pipeline::role::Series::$role.at(i), x)))
    };
    (@take One $role:ident, $n:ident) => { $n.one($crate::pipeline::role::Role::$role)? };
    (@take Maybe $role:ident, $n:ident) => { $n.maybe($crate::pipeline::role::Role::$role) };
    (@take Many $role:ident, $n:ident) => { $n.many($crate::pipeline::role::Series::$role) };
}

/// The inputs of a kind that reads none (it starts from its parameters).
#[derive(Debug, Clone, PartialEq)]
pub struct NoInputs<T>(std::marker::PhantomData<T>);

impl<T> Default for NoInputs<T> {
    fn default() -> Self {
        NoInputs(std::marker::PhantomData)
    }
}

impl<T> StageInputs<T> for NoInputs<T> {
    fn roles(&self) -> Vec<(Role, &T)> {
        Vec::new()
    }

    fn take(_: &mut Named<T>) -> Result<Self> {
        Ok(NoInputs::default())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    crate::stage_inputs! {
        Example { demos: One Demos, floor: Maybe Floor, sets: Many Set }
    }

    #[test]
    fn roles_round_trip_and_a_missing_repeated_or_unknown_role_is_refused() {
        let e = Example { demos: "d", floor: None, sets: vec!["a", "b"] };
        let roles: Vec<(Role, &&str)> = e.roles();
        assert_eq!(roles.iter().map(|(r, _)| r.name()).collect::<Vec<_>>(), ["demos", "set0", "set1"]);
        let mut named = Named::new("n", roles.into_iter().map(|(r, x)| (r, *x))).unwrap();
        assert_eq!(Example::take(&mut named).unwrap(), e);
        named.finish("example").unwrap();

        let mut missing = Named::new("n", [(Series::Set.at(0), "a")]).unwrap();
        assert!(Example::take(&mut missing).unwrap_err().to_string().contains("input 'demos' is missing"));
        assert!(Named::new("n", [(Role::Demos, "a"), (Role::Demos, "b")]).is_err());
        let mut extra = Named::new("n", [(Role::Demos, "d"), (Role::Judge, "j")]).unwrap();
        Example::take(&mut extra).unwrap();
        assert!(extra.finish("example").unwrap_err().to_string().contains("reads no input 'judge'"));
    }
}
