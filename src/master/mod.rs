//! The CANopen master, sans-I/O: state machines that take `(now, received frame)` and hand back
//! frames to send and typed events, in the style of [`crate::sim::SimDrive::poll`]. They never
//! read a clock, own a socket or start a thread; [`crate::gateway`] drives them over a real bus
//! and the tests over an in-memory one.

pub mod alarm;
pub mod cyclic;
pub mod supervision;
