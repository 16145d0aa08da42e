//! One table column per (task, algorithm) group: one function per metric family of the paper
//! (data cost, application, reliability, system in training and in inference), in table order.
//! The report's builder ([`super::build_report`]) calls them in that order.

pub(super) mod application;
pub(super) mod data_cost;
pub(super) mod reliability;
pub(super) mod system;
