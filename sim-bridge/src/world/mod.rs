//! The world: ego, background traffic, walkers, cyclists, static obstacles and traffic-light
//! controllers, advanced in 20 Hz lockstep.

pub mod state;
