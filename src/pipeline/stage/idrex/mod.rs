//! iD-REX's rollout stages: after D-REX, each iteration makes a new ranked set from the
//! current iteration's RL policies, in one of three ways: [`interpolation`] (variant 1),
//! [`action_noise`] (variant 2) and [`multi_bc`] (variant 3, whose clones are [`clone`]).
//! How the iterations join the DAG is in [`crate::pipeline::graph::idrex`].
pub mod action_noise;
pub mod clone;
pub mod interpolation;
pub mod multi_bc;
