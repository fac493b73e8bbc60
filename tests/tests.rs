//! Integration tests: one binary (linking libtorch once), one module per topic.
mod util;

mod bank;
mod bench;
mod bootstrap;
mod clone_filter;
mod defaults;
mod docs;
mod env_cli;
mod env_equivalence;
mod exp;
mod fuzz;
mod layout;
mod pipeline;
mod recording;
mod reliability;
mod report_html;
mod rliable;
mod s3_proxy;
mod screen;
mod skips;
mod sweep;
