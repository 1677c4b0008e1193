//! Training-side pieces of the network: the losses (imitation and future-BEV), with the special
//! functions they need.

pub mod loss;
pub mod special;
