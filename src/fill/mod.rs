//! Hole filling: what the methods are built from ([`kit`]), one module per method
//! (none imports another), and the dispatch that chooses, runs, checks and applies
//! them ([`dispatch`]).

pub mod advancing_front;
pub mod close;
pub mod dispatch;
pub mod fan;
pub mod hpde;
pub mod kit;
pub mod lssvm_poisson;
pub mod min_area_fair;
pub mod wavefront;
