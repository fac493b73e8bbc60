//! The pipeline engine: YAML experiment files ([`config`]) expand to a DAG of stage
//! instances ([`graph`], with iD-REX's iterations in [`idrex`]) whose results are
//! content-addressed artifacts in the store ([`crate::store`]); [`runner`] executes what is
//! missing; [`stage`] holds each kind's parameters, metrics and body.
pub mod config;
pub mod cores;
pub mod graph;
pub mod idrex;
pub mod plots;
pub mod recompute;
pub mod runner;
pub mod schedule;
pub mod slurm;
pub mod stage;

pub use config::{Method, Pipeline};
pub use graph::{Graph, Node, expand};
