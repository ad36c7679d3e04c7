//! Commissioning commands: the ecosystem's habits (`candump`, `cansend`, the CANopen tools of
//! every vendor) on top of the library's bus, SDO client and decoders.
//!
//! | Command | Library entry point |
//! |---|---|
//! | `canmotion monitor --bus IFACE [--machine FILE] [--log FILE] [--replay FILE]` | [`monitor::monitor`], [`monitor::replay`] (decoding: [`decode::decode`]) |
//! | `canmotion sdo read IFACE NODE INDEX[:SUB] [TYPE]` | [`sdo::read`] |
//! | `canmotion sdo write IFACE NODE INDEX[:SUB] TYPE VALUE` | [`sdo::write`] |
//! | `canmotion nmt IFACE start\|stop\|preop\|reset\|reset-comm NODE\|all` | [`nmt::send`] |
//! | `canmotion scan IFACE [--timeout-ms N]` | [`scan::scan`] |
//! | `canmotion reset IFACE NODE\|all` | [`reset::reset`] (fault reset, verified) |
//!
//! Every entry point takes a [`Bus`](crate::bus::Bus), so the same code runs on SocketCAN and on
//! the in-process bus with simulated drives (the tests in `tests/commissioning.rs`). The
//! argument types ([`Node`], [`ObjectAddress`], [`SdoType`], [`NmtCommand`], [`NmtTarget`])
//! implement `FromStr`, so the command line rejects malformed arguments with a usage message.
//!
//! Numbers follow the CANopen tools' conventions: object indices and sub-indices are
//! hexadecimal (`6040`, `0x6040:00`, `1018:4`), node ids and values are decimal unless written
//! with `0x`.

pub mod args;
pub mod candump;
pub mod decode;
pub mod monitor;
pub mod nmt;
pub mod reset;
pub mod scan;
pub mod sdo;

use std::path::PathBuf;

pub use args::{NmtCommand, NmtTarget, Node, ObjectAddress, SdoType};
pub use candump::{LogRecord, Timestamp};
pub use decode::{DecodeContext, Decoded, decode};

use crate::bus::BusError;
use crate::config::ConfigError;
use crate::gateway::GatewayError;

/// What can go wrong in a commissioning command; each message says which node, object, file or
/// line is concerned.
#[derive(Debug, thiserror::Error)]
pub enum ToolError {
    /// An SDO transfer, or the non-cyclic connection, failed (abort code and meaning included).
    #[error(transparent)]
    Gateway(#[from] GatewayError),
    /// The bus failed.
    #[error(transparent)]
    Bus(#[from] BusError),
    /// The machine file is wrong.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// An input is not a regular file, or a line of it is too long (see [`crate::files`]).
    #[error(transparent)]
    File(#[from] crate::files::FileError),
    /// A candump log line is malformed.
    #[error("{file}:{line}: {message}")]
    Log {
        /// The log file.
        file: String,
        /// 1-based line number.
        line: usize,
        /// What is wrong with the line.
        message: String,
    },
    /// A file could not be read or written.
    #[error("{file}: {source}")]
    Io {
        /// The file (or `stdout`).
        file: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A value given on the command line does not fit its type.
    #[error("{0}")]
    Value(String),
    /// A node answered an upload with a length that does not fit the requested type.
    #[error(
        "node {node}: SDO {index:04X}:{sub:02X} answered {got} byte(s), type {data_type} has {want}"
    )]
    TypeMismatch {
        /// Node.
        node: u8,
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// The requested type's name.
        data_type: &'static str,
        /// Bytes the node sent.
        got: usize,
        /// Bytes the type has.
        want: usize,
    },
}

/// A small tokio runtime for one command (the bus's async ports need one).
pub(crate) fn runtime() -> Result<tokio::runtime::Runtime, ToolError> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|source| ToolError::Io {
            file: PathBuf::from("tokio runtime"),
            source,
        })
}

/// `aa bb cc` for a byte slice (empty string for no bytes).
pub fn hex_bytes(data: &[u8]) -> String {
    let mut s = String::with_capacity(data.len() * 3);
    for (i, b) in data.iter().enumerate() {
        if i > 0 {
            s.push(' ');
        }
        s.push_str(&format!("{b:02X}"));
    }
    s
}
