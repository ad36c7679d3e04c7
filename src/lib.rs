//! canmotion (in progress)
pub mod bus;
pub mod canopen;
pub mod cia402;
pub mod config;
pub mod gateway;
pub mod gcode;
pub mod interp;
pub mod planner;
pub mod rt;
pub mod sim;
