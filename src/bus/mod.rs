//! The bus: one narrow interface over CAN frames.
mod frame;
pub use frame::Frame;
