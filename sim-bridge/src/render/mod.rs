//! Pictures for people: a top-down PNG of a route run (map, route, ego trace, actors,
//! infractions).

pub mod canvas;
pub mod topdown;
