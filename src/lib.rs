//! canmotion (in progress)
pub mod bus;
pub mod canopen;
pub mod cia402;
pub mod config;
pub mod gcode;
pub mod interp;
pub mod planner;
pub mod sim;
pub mod gateway;
pub mod rt;
