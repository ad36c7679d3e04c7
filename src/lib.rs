//! canmotion (in progress)
pub mod bus;
pub mod cia402;
pub mod gcode;
pub mod interp;
pub mod planner;
