//! The pipeline engine: YAML experiment files ([`config`]) expand to a DAG of stage
//! instances ([`graph`]) whose results are content-addressed artifacts in the store
//! ([`crate::store`]); [`runner`] executes what is missing; [`stages`] are the bodies.
pub mod config;
pub mod graph;
pub mod plots;
pub mod runner;
pub mod stages;

pub use config::{Method, Pipeline};
pub use graph::{Graph, Node, expand};
