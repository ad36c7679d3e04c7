//! The CANopen master, sans-I/O: state machines in the style of [`crate::sim::SimDrive::poll`]
//! (and of smoltcp). Each takes `(now, received frame)` or `poll(now)`, pushes the frames to send
//! into `out`, and returns where it stands (`Pending { poll_at }`, an event, or `Done` with a
//! typed result) or typed events. None reads a clock, owns a socket or spawns a thread: the
//! drivers in [`crate::gateway`] feed them from SocketCAN or the in-process bus, and the tests
//! feed them from simulated drives on a virtual clock (`tests/master_startup.rs`,
//! `tests/virtual_clock.rs`).
//!
//! - [`startup`]: NMT reset, boot-up wait, identity, position actual and the travel check, the
//!   machine file's SDO writes, PDO remap, mode confirmation, NMT start; and the orderly end
//!   (the drives stop consuming the gateway's heartbeat).
//! - [`cyclic`]: the enable walk and the cyclic streaming, with its typed [`alarm`]s.
//! - [`supervision`]: heartbeat consumer, EMCY (fault or warning by the statusword).

pub mod alarm;
pub mod cyclic;
pub mod startup;
pub mod supervision;
