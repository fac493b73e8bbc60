//! The pipeline engine: YAML experiment files ([`config`]) expand to a DAG of stage
//! instances ([`graph`]) whose results are content-addressed artifacts in the store
//! ([`crate::store`]); [`runner`] executes what is missing; [`stage`] holds each kind's
//! parameters, metrics and body.
//!
//! The layers, lowest first (each imports only those before it): [`kind`] (the stage kinds'
//! names and versions), [`config`] (the file's schema), [`stage`] (the bodies),
//! [`check`] (a parsed file's every check) and [`load`] (a file read and checked into a [`Pipeline`]), [`graph`] (the DAG), [`sweep`]
//! (a file's variants, their graphs joined),
//! [`calibrate`], [`schedule`] and [`cores`] (this processor's speed, ordering and threads), [`test_set`] (locked test sets),
//! [`gaps`] (BC far below its demonstrations), [`runner`], [`slurm`], [`recompute`] and
//! [`plots`].
pub mod calibrate;
pub mod check;
pub mod config;
pub mod cores;
pub mod gaps;
pub mod graph;
pub mod inputs;
pub mod kind;
pub mod load;
pub mod plots;
pub mod recompute;
pub mod role;
pub mod runner;
pub mod schedule;
pub mod slurm;
pub mod stage;
pub mod sweep;
pub mod test_set;

pub use config::Method;
pub use graph::{Graph, Node, expand};
pub use load::Pipeline;
pub use sweep::Sweep;
