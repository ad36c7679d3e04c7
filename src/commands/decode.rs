//! Decoding CAN frames per CiA 301 and CiA 402, for `canmotion monitor`: a pure function of the
//! frame and a [`DecodeContext`] (the SYNC COB-ID, and with a machine file its PDO mappings and
//! drive dictionaries).
//!
//! | COB-ID | Decoded as |
//! |---|---|
//! | 0x000 | NMT command `[cs, node]` (node 0 = all) |
//! | SYNC (0x080, or the machine's 0x1005) | SYNC, with its counter when it has one byte |
//! | 0x081–0x0FF | EMCY: code with its meaning, error register, vendor bytes |
//! | 0x100 | TIME |
//! | a machine PDO | its mapped objects: controlword with its CiA 402 command, statusword with its state and bits 10–13, positions in counts and mm |
//! | 0x180–0x57F otherwise | TPDO1–4 / RPDO1–4 of the node, raw |
//! | 0x581–0x5FF, 0x601–0x67F | SDO response / request: upload, download, segments, aborts with their meaning |
//! | 0x701–0x77F | heartbeat or boot-up with the NMT state; a remote frame is a node-guarding request |
//! | 0x7E4, 0x7E5 | LSS |
//!
//! Anything else, and any frame whose length does not fit its protocol, decodes as raw bytes
//! with what is wrong.

use std::collections::HashMap;
use std::fmt;
use std::sync::Arc;

use canopen_rs::Value;

use super::args::{NmtCommand, format_raw, format_value};
use super::hex_bytes;
use crate::bus::Frame;
use crate::canopen::index;
use crate::canopen::{AbortCode, Emcy, NmtState, cob};
use crate::cia402::{Command, State, statusword as sw};
use crate::config::machine::MapEntry;
use crate::config::{AxisMode, DriveDictionary, Machine};

/// Which way a PDO goes, seen from the drive (CiA 301 naming).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PdoDirection {
    /// Transmit PDO: drive → master (feedback).
    Tpdo,
    /// Receive PDO: master → drive (setpoints).
    Rpdo,
}

impl fmt::Display for PdoDirection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            PdoDirection::Tpdo => "TPDO",
            PdoDirection::Rpdo => "RPDO",
        })
    }
}

/// A PDO whose mapping is known (from a machine file).
#[derive(Debug, Clone)]
pub struct PdoLayout {
    /// TPDO or RPDO.
    pub direction: PdoDirection,
    /// PDO number 1–4.
    pub number: u8,
    /// The drive's node id.
    pub node: u8,
    /// The axis the drive moves.
    pub axis: Option<String>,
    /// The axis's position mode (names statusword bits 12/13 and controlword bit 4).
    pub mode: Option<AxisMode>,
    /// Encoder counts per millimetre, for positions in mm.
    pub counts_per_mm: Option<f64>,
    /// Mapped objects in frame order.
    pub mapping: Vec<MapEntry>,
}

/// What the decoder knows beyond the frame.
#[derive(Debug, Clone)]
pub struct DecodeContext {
    /// COB-ID of SYNC (0x1005, 11 bits).
    pub sync_cob_id: u16,
    pdos: HashMap<u16, PdoLayout>,
    dictionaries: HashMap<u8, Arc<DriveDictionary>>,
}

impl Default for DecodeContext {
    fn default() -> Self {
        DecodeContext::new()
    }
}

impl DecodeContext {
    /// No machine: SYNC on 0x080, PDOs raw by their COB-ID range.
    pub fn new() -> DecodeContext {
        DecodeContext {
            sync_cob_id: 0x080,
            pdos: HashMap::new(),
            dictionaries: HashMap::new(),
        }
    }

    /// A machine's SYNC COB-ID, the RPDO (setpoint) and TPDO (feedback) of every axis as
    /// mapped, and every drive's dictionary (names and types of SDO objects).
    pub fn from_machine(m: &Machine) -> DecodeContext {
        let mut ctx = DecodeContext::new();
        ctx.sync_cob_id = m.sync_cob_id & 0x7FF;
        for a in &m.axes {
            for (direction, pdo) in [
                (PdoDirection::Rpdo, &a.setpoint_pdo),
                (PdoDirection::Tpdo, &a.feedback_pdo),
            ] {
                ctx.add_pdo(
                    pdo.cob_id & 0x7FF,
                    PdoLayout {
                        direction,
                        number: pdo.number,
                        node: a.node,
                        axis: Some(a.name.clone()),
                        mode: Some(a.mode),
                        counts_per_mm: Some(a.counts_per_mm),
                        mapping: pdo.mapping.clone(),
                    },
                );
            }
            ctx.add_dictionary(a.node, a.dictionary.clone());
        }
        ctx
    }

    /// Decode frames on `cob_id` with `layout`.
    pub fn add_pdo(&mut self, cob_id: u16, layout: PdoLayout) {
        self.pdos.insert(cob_id, layout);
    }

    /// Name and type SDO objects of `node` from `dict`.
    pub fn add_dictionary(&mut self, node: u8, dict: Arc<DriveDictionary>) {
        self.dictionaries.insert(node, dict);
    }

    fn object_name(&self, node: u8, index: u16, sub: u8) -> Option<String> {
        let obj = self.dictionaries.get(&node)?.objects.get(&index)?;
        let s = obj.subs.get(&sub)?;
        Some(if obj.subs.len() == 1 && sub == 0 {
            obj.name.clone()
        } else {
            format!("{} / {}", obj.name, s.name)
        })
    }

    fn typed(&self, node: u8, index: u16, sub: u8, bytes: &[u8]) -> Option<String> {
        let def = self.dictionaries.get(&node)?.sub(index, sub)?;
        Value::decode_le(def.data_type, bytes)
            .ok()
            .map(|v| value_text(&v))
    }
}

/// A value as the monitor shows it: strings quoted, numbers with their hex form.
fn value_text(v: &Value) -> String {
    match v {
        Value::VisibleString(b) => match b.as_str() {
            Some(s) => format!("{s:?}"),
            None => hex_bytes(b.as_bytes()),
        },
        _ => format_value(v),
    }
}

/// Raw bytes as the monitor interprets them without a type: numbers for 1, 2, 4 and 8 bytes,
/// quoted text when printable.
fn raw_text(bytes: &[u8]) -> Option<String> {
    let printable = bytes.len() >= 2 && bytes.iter().all(|b| (0x20..0x7F).contains(b));
    (matches!(bytes.len(), 1 | 2 | 4 | 8) || printable).then(|| format_raw(bytes))
}

/// The data of an initiate download request or initiate upload response.
#[derive(Debug, Clone, PartialEq)]
pub enum SdoData {
    /// Expedited: the data travels in this frame.
    Expedited {
        /// The data bytes (4 when the size is not indicated).
        bytes: Vec<u8>,
        /// Whether the frame indicated the size.
        sized: bool,
        /// The value, typed from the dictionary when known.
        value: Option<String>,
    },
    /// Segmented: the data follows in segments.
    Segmented {
        /// Total size, when indicated.
        size: Option<u32>,
    },
}

/// One SDO frame (CiA 301 §7.2.4.3).
#[derive(Debug, Clone, PartialEq)]
pub enum SdoMessage {
    /// Client: initiate download (write).
    DownloadRequest {
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// Data or size.
        data: SdoData,
    },
    /// Client: download segment.
    DownloadSegment {
        /// Toggle bit.
        toggle: bool,
        /// Data bytes.
        data: Vec<u8>,
        /// No more segments.
        last: bool,
    },
    /// Client: initiate upload (read).
    UploadRequest {
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
    },
    /// Client: upload segment request.
    UploadSegmentRequest {
        /// Toggle bit.
        toggle: bool,
    },
    /// Server: initiate download response (acknowledge).
    DownloadResponse {
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
    },
    /// Server: download segment response.
    DownloadSegmentResponse {
        /// Toggle bit.
        toggle: bool,
    },
    /// Server: initiate upload response.
    UploadResponse {
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// Data or size.
        data: SdoData,
    },
    /// Server: upload segment.
    UploadSegment {
        /// Toggle bit.
        toggle: bool,
        /// Data bytes.
        data: Vec<u8>,
        /// No more segments.
        last: bool,
    },
    /// Either side: abort transfer.
    Abort {
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// The abort code (its meaning from [`AbortCode::meaning`]).
        code: AbortCode,
    },
    /// Block transfer frames (not decoded further).
    Block {
        /// The command specifier.
        cs: u8,
    },
    /// A command specifier CiA 301 does not define.
    Unknown {
        /// The command specifier.
        cs: u8,
    },
}

/// One mapped object of a decoded PDO.
#[derive(Debug, Clone, PartialEq)]
pub enum PdoField {
    /// Controlword 0x6040.
    Controlword {
        /// The word.
        value: u16,
        /// The axis's mode (names bit 4).
        mode: Option<AxisMode>,
    },
    /// Statusword 0x6041.
    Statusword {
        /// The word.
        value: u16,
        /// The axis's mode (names bits 12 and 13).
        mode: Option<AxisMode>,
    },
    /// A position object (0x6064, 0x60C1:01, 0x607A, 0x6062, 0x60FC, 0x60F4).
    Position {
        /// Its name.
        label: &'static str,
        /// In encoder counts.
        counts: i32,
        /// In millimetres, when the machine gives the scaling.
        mm: Option<f64>,
    },
    /// Any other mapped object.
    Other {
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// Its name, from the dictionary.
        name: Option<String>,
        /// Its bytes.
        bytes: Vec<u8>,
        /// Its value, typed from the dictionary when known.
        value: Option<String>,
    },
}

/// The content of a PDO.
#[derive(Debug, Clone, PartialEq)]
pub enum PdoContent {
    /// No mapping known: the bytes.
    Raw(Vec<u8>),
    /// Decoded through the machine's mapping.
    Mapped {
        /// The objects that fit in the frame, in order.
        fields: Vec<PdoField>,
        /// A length that does not match the mapping.
        problem: Option<String>,
    },
}

/// A decoded frame; [`fmt::Display`] gives the monitor's text.
#[derive(Debug, Clone, PartialEq)]
pub enum Decoded {
    /// NMT node control.
    Nmt {
        /// The command.
        command: NmtCommand,
        /// The node (0 = all).
        node: u8,
    },
    /// SYNC.
    Sync {
        /// The counter (0x1019 > 1), when the frame has one byte.
        counter: Option<u8>,
    },
    /// TIME stamp (CiA 301 TIME_OF_DAY).
    Time {
        /// Milliseconds after midnight.
        ms: u32,
        /// Days since 1984-01-01.
        days: u16,
    },
    /// Emergency.
    Emcy(Emcy),
    /// Heartbeat, boot-up or node-guarding reply.
    Heartbeat {
        /// The node.
        node: u8,
        /// Its NMT state.
        state: NmtState,
        /// Bit 7 (the node-guarding toggle).
        toggle: bool,
    },
    /// A remote frame (node guarding, or a PDO request).
    Remote {
        /// What it asks for.
        of: String,
    },
    /// SDO.
    Sdo {
        /// The server node.
        node: u8,
        /// Client → server (0x600 + node) rather than server → client (0x580 + node).
        request: bool,
        /// The message.
        message: SdoMessage,
        /// The object's name from the dictionary, when known.
        object: Option<String>,
    },
    /// Process data.
    Pdo {
        /// TPDO or RPDO.
        direction: PdoDirection,
        /// PDO number 1–4.
        number: u8,
        /// The drive.
        node: u8,
        /// Its axis.
        axis: Option<String>,
        /// Decoded or raw content.
        content: PdoContent,
    },
    /// Layer setting services.
    Lss {
        /// Master → slave (0x7E5) rather than slave → master (0x7E4).
        request: bool,
        /// The bytes.
        data: Vec<u8>,
    },
    /// A frame of a known kind that does not fit its protocol.
    Malformed {
        /// What kind of frame it is (`EMCY node 3`).
        what: String,
        /// What is wrong.
        problem: String,
        /// The bytes.
        data: Vec<u8>,
    },
    /// A COB-ID no protocol here claims.
    Unknown {
        /// The identifier.
        id: u16,
        /// The bytes.
        data: Vec<u8>,
    },
}

/// Decode one frame.
pub fn decode(frame: &Frame, ctx: &DecodeContext) -> Decoded {
    let id = frame.id();
    let data = frame.data();
    let node = (id & 0x7F) as u8;
    let malformed = |what: String, problem: String| Decoded::Malformed {
        what,
        problem,
        data: data.to_vec(),
    };
    if frame.is_remote() {
        let of = if (cob::HEARTBEAT + 1..=cob::HEARTBEAT + 127).contains(&id) {
            format!("node guarding of node {node}")
        } else if let Some(l) = ctx.pdos.get(&id) {
            format!("{}{} of node {}", l.direction, l.number, l.node)
        } else if let Some((dir, n)) = pdo_range(id) {
            format!("{dir}{n} of node {node}")
        } else {
            format!("COB-ID 0x{id:03X}")
        };
        return Decoded::Remote { of };
    }
    if id == cob::NMT {
        return match data {
            [cs, n] => match NmtCommand::from_cs(*cs) {
                Some(command) => Decoded::Nmt { command, node: *n },
                None => malformed(
                    "NMT".into(),
                    format!("unknown command specifier 0x{cs:02X}"),
                ),
            },
            _ => malformed("NMT".into(), format!("{} bytes, expected 2", data.len())),
        };
    }
    if id == ctx.sync_cob_id {
        return match data {
            [] => Decoded::Sync { counter: None },
            [c] => Decoded::Sync { counter: Some(*c) },
            _ => malformed(
                "SYNC".into(),
                format!(
                    "{} bytes, expected 0 or 1 (drives answer EMCY 0x8240)",
                    data.len()
                ),
            ),
        };
    }
    if let Some(layout) = ctx.pdos.get(&id) {
        return Decoded::Pdo {
            direction: layout.direction,
            number: layout.number,
            node: layout.node,
            axis: layout.axis.clone(),
            content: decode_mapped(layout, data, ctx),
        };
    }
    match id {
        0x081..=0x0FF => match Emcy::from_frame(frame) {
            Some(e) => Decoded::Emcy(e),
            None => malformed(
                format!("EMCY node {node}"),
                format!("{} bytes, expected 8", data.len()),
            ),
        },
        0x100 => match data {
            [a, b, c, d, e, f] => Decoded::Time {
                ms: u32::from_le_bytes([*a, *b, *c, *d]) & 0x0FFF_FFFF,
                days: u16::from_le_bytes([*e, *f]),
            },
            _ => malformed("TIME".into(), format!("{} bytes, expected 6", data.len())),
        },
        0x581..=0x5FF | 0x601..=0x67F => {
            let request = id >= cob::SDO_RX;
            let what = || {
                format!(
                    "SDO node {node} {}",
                    if request { "request" } else { "response" }
                )
            };
            let Ok(p) = <[u8; 8]>::try_from(data) else {
                return malformed(what(), format!("{} bytes, expected 8", data.len()));
            };
            let message = decode_sdo(node, request, &p, ctx);
            let object = match &message {
                SdoMessage::DownloadRequest { index, sub, .. }
                | SdoMessage::UploadRequest { index, sub }
                | SdoMessage::DownloadResponse { index, sub }
                | SdoMessage::UploadResponse { index, sub, .. }
                | SdoMessage::Abort { index, sub, .. } => ctx.object_name(node, *index, *sub),
                _ => None,
            };
            Decoded::Sdo {
                node,
                request,
                message,
                object,
            }
        }
        0x701..=0x77F => match data {
            [b] => match NmtState::from_byte(*b) {
                Some(state) => Decoded::Heartbeat {
                    node,
                    state,
                    toggle: b & 0x80 != 0,
                },
                None => malformed(
                    format!("heartbeat node {node}"),
                    format!("unknown NMT state 0x{b:02X}"),
                ),
            },
            _ => malformed(
                format!("heartbeat node {node}"),
                format!("{} bytes, expected 1", data.len()),
            ),
        },
        0x7E4 | 0x7E5 => Decoded::Lss {
            request: id == 0x7E5,
            data: data.to_vec(),
        },
        _ => match pdo_range(id) {
            Some((direction, number)) => Decoded::Pdo {
                direction,
                number,
                node,
                axis: None,
                content: PdoContent::Raw(data.to_vec()),
            },
            None => Decoded::Unknown {
                id,
                data: data.to_vec(),
            },
        },
    }
}

/// TPDO1–4 / RPDO1–4 of the predefined connection set (node ids 1–127).
fn pdo_range(id: u16) -> Option<(PdoDirection, u8)> {
    if id & 0x7F == 0 {
        return None;
    }
    let base = id & 0x780;
    if let Some(n) = cob::TPDO.iter().position(|&b| b == base) {
        return Some((PdoDirection::Tpdo, n as u8 + 1));
    }
    cob::RPDO
        .iter()
        .position(|&b| b == base)
        .map(|n| (PdoDirection::Rpdo, n as u8 + 1))
}

fn decode_sdo(node: u8, request: bool, p: &[u8; 8], ctx: &DecodeContext) -> SdoMessage {
    let cs = p[0] >> 5;
    let index = u16::from_le_bytes([p[1], p[2]]);
    let sub = p[3];
    let toggle = p[0] & 0x10 != 0;
    let segment = || {
        let n = usize::from((p[0] >> 1) & 0x07);
        (p[1..8 - n].to_vec(), p[0] & 0x01 != 0)
    };
    let initiate_data = || {
        let e = p[0] & 0x02 != 0;
        let s = p[0] & 0x01 != 0;
        if e {
            let len = if s {
                4 - usize::from((p[0] >> 2) & 0x03)
            } else {
                4
            };
            let bytes = p[4..4 + len].to_vec();
            let value = ctx
                .typed(node, index, sub, &bytes)
                .or_else(|| raw_text(&bytes));
            SdoData::Expedited {
                bytes,
                sized: s,
                value,
            }
        } else {
            SdoData::Segmented {
                size: s.then(|| u32::from_le_bytes([p[4], p[5], p[6], p[7]])),
            }
        }
    };
    if p[0] == 0x80 {
        return SdoMessage::Abort {
            index,
            sub,
            code: AbortCode(u32::from_le_bytes([p[4], p[5], p[6], p[7]])),
        };
    }
    match (request, cs) {
        (true, 1) => SdoMessage::DownloadRequest {
            index,
            sub,
            data: initiate_data(),
        },
        (true, 0) => {
            let (data, last) = segment();
            SdoMessage::DownloadSegment { toggle, data, last }
        }
        (true, 2) => SdoMessage::UploadRequest { index, sub },
        (true, 3) => SdoMessage::UploadSegmentRequest { toggle },
        (false, 3) => SdoMessage::DownloadResponse { index, sub },
        (false, 1) => SdoMessage::DownloadSegmentResponse { toggle },
        (false, 2) => SdoMessage::UploadResponse {
            index,
            sub,
            data: initiate_data(),
        },
        (false, 0) => {
            let (data, last) = segment();
            SdoMessage::UploadSegment { toggle, data, last }
        }
        (_, 5 | 6) => SdoMessage::Block { cs },
        _ => SdoMessage::Unknown { cs },
    }
}

fn position_label(index: u16, sub: u8) -> Option<&'static str> {
    Some(match (index, sub) {
        (index::POSITION_ACTUAL, 0) => "position actual",
        (index::IP_DATA_RECORD, 1) => "IP setpoint",
        (index::TARGET_POSITION, 0) => "target position",
        (index::POSITION_DEMAND, 0) => "position demand",
        (index::POSITION_DEMAND_INTERNAL, 0) => "position demand (internal)",
        (index::FOLLOWING_ERROR_ACTUAL, 0) => "following error actual",
        _ => return None,
    })
}

fn decode_mapped(layout: &PdoLayout, data: &[u8], ctx: &DecodeContext) -> PdoContent {
    let mut fields = Vec::new();
    let mut off = 0usize;
    let need: usize = layout.mapping.iter().map(|e| usize::from(e.bits / 8)).sum();
    for e in &layout.mapping {
        let n = usize::from(e.bits / 8);
        let Some(bytes) = data.get(off..off + n) else {
            break;
        };
        off += n;
        let field = match (e.index, e.sub, bytes) {
            (index::CONTROLWORD, 0, [a, b]) => PdoField::Controlword {
                value: u16::from_le_bytes([*a, *b]),
                mode: layout.mode,
            },
            (index::STATUSWORD, 0, [a, b]) => PdoField::Statusword {
                value: u16::from_le_bytes([*a, *b]),
                mode: layout.mode,
            },
            (i, s, [a, b, c, d]) if position_label(i, s).is_some() => {
                let counts = i32::from_le_bytes([*a, *b, *c, *d]);
                PdoField::Position {
                    label: position_label(i, s).expect("checked"),
                    counts,
                    mm: layout
                        .counts_per_mm
                        .filter(|c| *c != 0.0)
                        .map(|c| f64::from(counts) / c),
                }
            }
            (index, sub, bytes) => PdoField::Other {
                index,
                sub,
                name: ctx.object_name(layout.node, index, sub),
                bytes: bytes.to_vec(),
                value: ctx
                    .typed(layout.node, index, sub, bytes)
                    .or_else(|| raw_text(bytes)),
            },
        };
        fields.push(field);
    }
    let problem = (data.len() != need).then(|| {
        format!(
            "{} bytes, the mapping has {need} (drives answer EMCY {})",
            data.len(),
            if data.len() < need {
                "0x8210"
            } else {
                "0x8220"
            }
        )
    });
    PdoContent::Mapped { fields, problem }
}

fn controlword_text(cw: u16, mode: Option<AxisMode>) -> String {
    let mut s = format!("controlword 0x{cw:04X}");
    if let Some(c) = Command::from_controlword(cw, 0) {
        s.push_str(&format!(" {c}"));
    }
    if cw & crate::cia402::controlword::IP_ENABLE != 0 {
        s.push_str(match mode {
            Some(AxisMode::Ip) => ", enable IP (bit 4)",
            _ => ", bit 4",
        });
    }
    if cw & crate::cia402::controlword::HALT != 0 {
        s.push_str(", halt");
    }
    s
}

fn statusword_text(w: u16, mode: Option<AxisMode>) -> String {
    let mut s = format!("statusword 0x{w:04X} ");
    match State::from_statusword(w) {
        Some(st) => s.push_str(st.name()),
        None => s.push_str("(no valid state)"),
    }
    let bits: [(u16, &str); 5] = [
        (sw::WARNING, "warning"),
        (sw::TARGET_REACHED, "target reached"),
        (sw::INTERNAL_LIMIT, "internal limit"),
        (
            sw::OP_MODE_SPECIFIC_12,
            match mode {
                Some(AxisMode::Ip) => "IP active",
                Some(AxisMode::Csp) => "following setpoint",
                None => "bit 12",
            },
        ),
        (
            sw::OP_MODE_SPECIFIC_13,
            match mode {
                Some(AxisMode::Csp) => "following error",
                _ => "bit 13",
            },
        ),
    ];
    for (bit, name) in bits {
        if w & bit != 0 {
            s.push_str(", ");
            s.push_str(name);
        }
    }
    s
}

impl fmt::Display for PdoField {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PdoField::Controlword { value, mode } => f.write_str(&controlword_text(*value, *mode)),
            PdoField::Statusword { value, mode } => f.write_str(&statusword_text(*value, *mode)),
            PdoField::Position { label, counts, mm } => {
                write!(f, "{label} {counts} counts")?;
                if let Some(mm) = mm {
                    write!(f, " ({mm:.3} mm)")?;
                }
                Ok(())
            }
            PdoField::Other {
                index,
                sub,
                name,
                bytes,
                value,
            } => {
                write!(f, "{index:04X}:{sub:02X}")?;
                if let Some(n) = name {
                    write!(f, " {n}")?;
                }
                write!(f, " {}", hex_bytes(bytes))?;
                if let Some(v) = value {
                    write!(f, " = {v}")?;
                }
                Ok(())
            }
        }
    }
}

fn object_suffix(f: &mut fmt::Formatter<'_>, object: &Option<String>) -> fmt::Result {
    match object {
        Some(name) => write!(f, " {name}"),
        None => Ok(()),
    }
}

fn segment_text(f: &mut fmt::Formatter<'_>, toggle: bool, data: &[u8], last: bool) -> fmt::Result {
    write!(f, " (toggle {}", u8::from(toggle))?;
    if last {
        f.write_str(", last")?;
    }
    write!(f, "): {}", hex_bytes(data))?;
    if !data.is_empty() && data.iter().all(|b| (0x20..0x7F).contains(b)) {
        write!(f, " {:?}", String::from_utf8_lossy(data))?;
    }
    Ok(())
}

fn sdo_data_text(f: &mut fmt::Formatter<'_>, data: &SdoData) -> fmt::Result {
    match data {
        SdoData::Expedited {
            bytes,
            sized,
            value,
        } => {
            write!(f, ": {}", hex_bytes(bytes))?;
            if let Some(v) = value {
                write!(f, " = {v}")?;
            }
            if !sized {
                f.write_str(" (size not indicated)")?;
            }
            Ok(())
        }
        SdoData::Segmented { size: Some(n) } => write!(f, ": segmented, {n} bytes"),
        SdoData::Segmented { size: None } => f.write_str(": segmented, size not indicated"),
    }
}

impl fmt::Display for Decoded {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Decoded::Nmt { command, node } => {
                write!(f, "NMT {command}: ")?;
                if *node == 0 {
                    f.write_str("all nodes")
                } else {
                    write!(f, "node {node}")
                }
            }
            Decoded::Sync { counter: None } => f.write_str("SYNC"),
            Decoded::Sync { counter: Some(c) } => write!(f, "SYNC counter {c}"),
            Decoded::Time { ms, days } => {
                let s = ms / 1000;
                write!(
                    f,
                    "TIME {:02}:{:02}:{:02}.{:03}, day {days} since 1984-01-01",
                    s / 3600,
                    s / 60 % 60,
                    s % 60,
                    ms % 1000
                )
            }
            Decoded::Emcy(e) => {
                write!(
                    f,
                    "EMCY node {}: 0x{:04X} {}, error register 0x{:02X}",
                    e.node,
                    e.code,
                    crate::canopen::emcy::meaning(e.code),
                    e.register
                )?;
                if e.vendor != [0; 5] {
                    write!(f, ", vendor {}", hex_bytes(&e.vendor))?;
                }
                Ok(())
            }
            Decoded::Heartbeat {
                node,
                state: NmtState::BootUp,
                ..
            } => write!(f, "boot-up node {node}"),
            Decoded::Heartbeat {
                node,
                state,
                toggle,
            } => {
                write!(f, "heartbeat node {node}: {state}")?;
                if *toggle {
                    f.write_str(" (toggle bit set: node-guarding reply)")?;
                }
                Ok(())
            }
            Decoded::Remote { of } => write!(f, "remote request: {of}"),
            Decoded::Sdo {
                node,
                request,
                message,
                object,
            } => {
                write!(f, "SDO node {node} ")?;
                match message {
                    SdoMessage::DownloadRequest { index, sub, data } => {
                        write!(f, "download request {index:04X}:{sub:02X}")?;
                        object_suffix(f, object)?;
                        sdo_data_text(f, data)
                    }
                    SdoMessage::DownloadSegment { toggle, data, last } => {
                        f.write_str("download segment")?;
                        segment_text(f, *toggle, data, *last)
                    }
                    SdoMessage::UploadRequest { index, sub } => {
                        write!(f, "upload request {index:04X}:{sub:02X}")?;
                        object_suffix(f, object)
                    }
                    SdoMessage::UploadSegmentRequest { toggle } => {
                        write!(f, "upload segment request (toggle {})", u8::from(*toggle))
                    }
                    SdoMessage::DownloadResponse { index, sub } => {
                        write!(f, "download response {index:04X}:{sub:02X}")?;
                        object_suffix(f, object)?;
                        f.write_str(": ok")
                    }
                    SdoMessage::DownloadSegmentResponse { toggle } => {
                        write!(
                            f,
                            "download segment response (toggle {})",
                            u8::from(*toggle)
                        )
                    }
                    SdoMessage::UploadResponse { index, sub, data } => {
                        write!(f, "upload response {index:04X}:{sub:02X}")?;
                        object_suffix(f, object)?;
                        sdo_data_text(f, data)
                    }
                    SdoMessage::UploadSegment { toggle, data, last } => {
                        f.write_str("upload segment")?;
                        segment_text(f, *toggle, data, *last)
                    }
                    SdoMessage::Abort { index, sub, code } => {
                        write!(
                            f,
                            "abort by {} {index:04X}:{sub:02X}",
                            if *request { "client" } else { "server" }
                        )?;
                        object_suffix(f, object)?;
                        write!(f, ": {code}")
                    }
                    SdoMessage::Block { cs } => write!(
                        f,
                        "block transfer {} (command specifier {cs})",
                        if *request { "request" } else { "response" }
                    ),
                    SdoMessage::Unknown { cs } => write!(
                        f,
                        "{} with unknown command specifier {cs}",
                        if *request { "request" } else { "response" }
                    ),
                }
            }
            Decoded::Pdo {
                direction,
                number,
                node,
                axis,
                content,
            } => {
                write!(f, "{direction}{number} node {node}")?;
                if let Some(a) = axis {
                    write!(f, " (axis {a})")?;
                }
                f.write_str(":")?;
                match content {
                    PdoContent::Raw(d) if d.is_empty() => f.write_str(" (no data)"),
                    PdoContent::Raw(d) => write!(f, " {}", hex_bytes(d)),
                    PdoContent::Mapped { fields, problem } => {
                        for (i, field) in fields.iter().enumerate() {
                            write!(f, "{} {field}", if i == 0 { "" } else { ";" })?;
                        }
                        if let Some(p) = problem {
                            write!(f, " [{p}]")?;
                        }
                        Ok(())
                    }
                }
            }
            Decoded::Lss { request, data } => write!(
                f,
                "LSS {}: {}",
                if *request { "request" } else { "response" },
                hex_bytes(data)
            ),
            Decoded::Malformed {
                what,
                problem,
                data,
            } => {
                write!(f, "{what}: malformed, {problem}")?;
                if !data.is_empty() {
                    write!(f, ": {}", hex_bytes(data))?;
                }
                Ok(())
            }
            Decoded::Unknown { id, data } => {
                write!(f, "unknown COB-ID 0x{id:03X}")?;
                if !data.is_empty() {
                    write!(f, ": {}", hex_bytes(data))?;
                }
                Ok(())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::commands::candump::parse_frame;

    fn d(frame: &str) -> String {
        decode(&parse_frame(frame).unwrap(), &DecodeContext::new()).to_string()
    }

    fn dm(frame: &str) -> String {
        let ctx = DecodeContext::from_machine(&Machine::demo());
        decode(&parse_frame(frame).unwrap(), &ctx).to_string()
    }

    #[test]
    fn nmt_commands() {
        // Checklist: frame 0x000 [cs, node], node 0 = all; cs 01 02 80 81 82.
        assert_eq!(d("000#0105"), "NMT start: node 5");
        assert_eq!(d("000#0200"), "NMT stop: all nodes");
        assert_eq!(d("000#8001"), "NMT enter pre-operational: node 1");
        assert_eq!(d("000#817F"), "NMT reset node: node 127");
        assert_eq!(d("000#8200"), "NMT reset communication: all nodes");
        assert_eq!(
            d("000#0305"),
            "NMT: malformed, unknown command specifier 0x03: 03 05"
        );
        assert_eq!(d("000#01"), "NMT: malformed, 1 bytes, expected 2: 01");
    }

    #[test]
    fn sync_with_and_without_counter() {
        assert_eq!(d("080#"), "SYNC");
        assert_eq!(d("080#03"), "SYNC counter 3");
        assert_eq!(
            d("080#0102"),
            "SYNC: malformed, 2 bytes, expected 0 or 1 (drives answer EMCY 0x8240): 01 02"
        );
    }

    #[test]
    fn emcy_with_meaning() {
        // 0x8611 following error, error register 0x21, from node 3.
        assert_eq!(
            d("083#1186210000000000"),
            "EMCY node 3: 0x8611 following error, error register 0x21"
        );
        assert_eq!(
            d("081#0000000000000000"),
            "EMCY node 1: 0x0000 error reset or no error, error register 0x00"
        );
        assert_eq!(
            d("082#3081110102030405"),
            "EMCY node 2: 0x8130 life guard or heartbeat error, error register 0x11, vendor 01 02 03 04 05"
        );
        for (code, text) in [
            ("1023", "continuous over-current"),
            ("1032", "DC-link over-voltage"),
            ("2032", "DC-link under-voltage"),
            ("1043", "excess drive temperature"),
            ("1081", "CAN overrun"),
            ("2081", "error passive"),
            ("4081", "recovered from bus off"),
            ("5082", "RPDO timeout"),
            ("1082", "PDO not processed due to length error"),
            ("2082", "PDO length exceeded"),
            ("4082", "unexpected SYNC data length"),
            ("0081", "SYNC missing"),
        ] {
            let s = d(&format!("081#{code}010000000000"));
            assert!(s.contains(text), "{s}");
        }
        assert_eq!(
            d("081#1186"),
            "EMCY node 1: malformed, 2 bytes, expected 8: 11 86"
        );
    }

    #[test]
    fn heartbeats_and_boot_up() {
        assert_eq!(d("705#00"), "boot-up node 5");
        assert_eq!(d("705#04"), "heartbeat node 5: stopped");
        assert_eq!(d("705#05"), "heartbeat node 5: operational");
        assert_eq!(d("705#7F"), "heartbeat node 5: pre-operational");
        assert_eq!(
            d("705#85"),
            "heartbeat node 5: operational (toggle bit set: node-guarding reply)"
        );
        assert_eq!(
            d("705#03"),
            "heartbeat node 5: malformed, unknown NMT state 0x03: 03"
        );
        assert_eq!(d("705#R1"), "remote request: node guarding of node 5");
    }

    #[test]
    fn sdo_expedited_transfers() {
        // Download 2 bytes (0x2B) to 0x6040:00, acknowledged with 0x60.
        assert_eq!(
            d("601#2B40600006000000"),
            "SDO node 1 download request 6040:00: 06 00 = 6 (0x0006)"
        );
        assert_eq!(
            d("581#6040600000000000"),
            "SDO node 1 download response 6040:00: ok"
        );
        // 4, 3, 1 bytes: 0x23, 0x27, 0x2F.
        assert_eq!(
            d("601#2317100064000000"),
            "SDO node 1 download request 1017:00: 64 00 00 00 = 100 (0x00000064)"
        );
        assert_eq!(
            d("601#2700200001020300"),
            "SDO node 1 download request 2000:00: 01 02 03"
        );
        assert_eq!(
            d("601#2F60600007000000"),
            "SDO node 1 download request 6060:00: 07 = 7 (0x07)"
        );
        // Upload: request 0x40, response 0x43 (4 bytes), 0x4B (2 bytes).
        assert_eq!(
            d("605#4000100000000000"),
            "SDO node 5 upload request 1000:00"
        );
        assert_eq!(
            d("585#4300100092010200"),
            "SDO node 5 upload response 1000:00: 92 01 02 00 = 131474 (0x00020192)"
        );
        assert_eq!(
            d("585#4B41600037020000"),
            "SDO node 5 upload response 6041:00: 37 02 = 567 (0x0237)"
        );
    }

    #[test]
    fn sdo_segmented_transfers() {
        assert_eq!(
            d("585#4108100013000000"),
            "SDO node 5 upload response 1008:00: segmented, 19 bytes"
        );
        assert_eq!(
            d("605#6000000000000000"),
            "SDO node 5 upload segment request (toggle 0)"
        );
        assert_eq!(
            d("585#0063616E6D6F7469"),
            "SDO node 5 upload segment (toggle 0): 63 61 6E 6D 6F 74 69 \"canmoti\""
        );
        assert_eq!(
            d("585#1B73650000000000"),
            "SDO node 5 upload segment (toggle 1, last): 73 65 \"se\""
        );
        assert_eq!(
            d("605#2108100013000000"),
            "SDO node 5 download request 1008:00: segmented, 19 bytes"
        );
        assert_eq!(
            d("605#1941424300000000"),
            "SDO node 5 download segment (toggle 1, last): 41 42 43 \"ABC\""
        );
        assert_eq!(
            d("585#3000000000000000"),
            "SDO node 5 download segment response (toggle 1)"
        );
    }

    #[test]
    fn sdo_aborts_with_their_meaning() {
        for (code, text) in [
            ("00000405", "0x05040000 (SDO protocol timed out)"),
            ("00000106", "0x06010000 (unsupported access to an object)"),
            (
                "02000106",
                "0x06010002 (attempt to write a read-only object)",
            ),
            (
                "00000206",
                "0x06020000 (object does not exist in the object dictionary)",
            ),
            (
                "41000406",
                "0x06040041 (object cannot be mapped to the PDO)",
            ),
            (
                "42000406",
                "0x06040042 (the mapped objects would exceed the PDO length)",
            ),
            (
                "10000706",
                "0x06070010 (data type does not match, length of service parameter does not match)",
            ),
            ("11000906", "0x06090011 (sub-index does not exist)"),
            ("30000906", "0x06090030 (invalid value for parameter)"),
            (
                "31000906",
                "0x06090031 (value of parameter written too high)",
            ),
            (
                "32000906",
                "0x06090032 (value of parameter written too low)",
            ),
            (
                "22000008",
                "0x08000022 (data cannot be transferred or stored because of the present device state)",
            ),
        ] {
            assert_eq!(
                d(&format!("581#80416000{code}")),
                format!("SDO node 1 abort by server 6041:00: {text}")
            );
        }
        assert_eq!(
            d("601#8040600000000405"),
            "SDO node 1 abort by client 6040:00: 0x05040000 (SDO protocol timed out)"
        );
        assert_eq!(
            d("601#2B4060"),
            "SDO node 1 request: malformed, 3 bytes, expected 8: 2B 40 60"
        );
    }

    #[test]
    fn sdo_objects_are_named_and_typed_with_a_machine() {
        assert_eq!(
            dm("601#2B40600006000000"),
            "SDO node 1 download request 6040:00 Controlword: 06 00 = 6 (0x0006)"
        );
        assert_eq!(
            dm("581#43181001A70C0000"),
            "SDO node 1 upload response 1018:01 Identity object / Vendor-ID: A7 0C 00 00 = 3239 (0x00000CA7)"
        );
    }

    #[test]
    fn pdos_raw_without_a_machine() {
        assert_eq!(d("181#3716E8030000"), "TPDO1 node 1: 37 16 E8 03 00 00");
        assert_eq!(d("201#1F0050C30000"), "RPDO1 node 1: 1F 00 50 C3 00 00");
        assert_eq!(d("285#01"), "TPDO2 node 5: 01");
        assert_eq!(d("30A#"), "RPDO2 node 10: (no data)");
        assert_eq!(d("48F#00"), "TPDO4 node 15: 00");
        assert_eq!(d("57F#00"), "RPDO4 node 127: 00");
        assert_eq!(d("181#R"), "remote request: TPDO1 of node 1");
        assert_eq!(d("180#00"), "unknown COB-ID 0x180: 00");
        assert_eq!(d("123#R"), "remote request: COB-ID 0x123");
    }

    #[test]
    fn pdos_through_the_machine_mapping() {
        // lib.rs's example: X on node 1, RPDO 0x60400010 0x60C10120, 1000 counts/mm.
        assert_eq!(
            dm("201#1F0050C30000"),
            "RPDO1 node 1 (axis X): controlword 0x001F Enable operation, enable IP (bit 4); IP setpoint 50000 counts (50.000 mm)"
        );
        assert_eq!(
            dm("181#3716E8030000"),
            "TPDO1 node 1 (axis X): statusword 0x1637 Operation enabled, target reached, IP active; position actual 1000 counts (1.000 mm)"
        );
        // Z: 2000 counts/mm.
        assert_eq!(
            dm("183#0822F0D8FFFF"),
            "TPDO1 node 3 (axis Z): statusword 0x2208 Fault, bit 13; position actual -10000 counts (-5.000 mm)"
        );
        assert_eq!(
            dm("202#86000000000000"),
            "RPDO1 node 2 (axis Y): controlword 0x0086 Fault reset; IP setpoint 0 counts (0.000 mm) [7 bytes, the mapping has 6 (drives answer EMCY 0x8220)]"
        );
        assert_eq!(
            dm("182#4002"),
            "TPDO1 node 2 (axis Y): statusword 0x0240 Switch on disabled [2 bytes, the mapping has 6 (drives answer EMCY 0x8210)]"
        );
        for (cw, text) in [
            ("0600", "Shutdown"),
            ("0700", "Switch on / Disable operation"),
            ("0F00", "Enable operation"),
            ("0000", "Disable voltage"),
            ("0200", "Quick stop"),
            ("0F01", "Enable operation, halt"),
        ] {
            let s = dm(&format!("201#{cw}00000000"));
            assert!(
                s.contains(&format!("controlword 0x{}{} {text}", &cw[2..], &cw[..2])),
                "{s}"
            );
        }
        for (sw, text) in [
            ("0000", "Not ready to switch on"),
            ("5000", "Switch on disabled"),
            ("3100", "Ready to switch on"),
            ("3300", "Switched on"),
            ("1700", "Quick stop active"),
            ("1F00", "Fault reaction active"),
            ("B708", "Operation enabled, warning, internal limit"),
            ("0100", "(no valid state)"),
        ] {
            let s = dm(&format!("181#{sw}00000000"));
            assert!(s.contains(text), "{s}");
        }
        // Other nodes' PDOs stay raw.
        assert_eq!(dm("184#0102"), "TPDO1 node 4: 01 02");
    }

    #[test]
    fn csp_names_bits_12_and_13() {
        let m = Machine::demo();
        let mut ctx = DecodeContext::from_machine(&m);
        ctx.add_pdo(
            0x185,
            PdoLayout {
                direction: PdoDirection::Tpdo,
                number: 1,
                node: 5,
                axis: Some("A".into()),
                mode: Some(AxisMode::Csp),
                counts_per_mm: None,
                mapping: vec![
                    MapEntry::from_u32(0x60410010),
                    MapEntry::from_u32(0x60640020),
                ],
            },
        );
        assert_eq!(
            decode(&parse_frame("185#3730FFFFFFFF").unwrap(), &ctx).to_string(),
            "TPDO1 node 5 (axis A): statusword 0x3037 Operation enabled, following setpoint, following error; position actual -1 counts"
        );
    }

    #[test]
    fn other_frames() {
        assert_eq!(
            d("100#E8030000FF38"),
            "TIME 00:00:01.000, day 14591 since 1984-01-01"
        );
        assert_eq!(
            d("7E5#0401000000000000"),
            "LSS request: 04 01 00 00 00 00 00 00"
        );
        assert_eq!(d("7E4#44"), "LSS response: 44");
        assert_eq!(d("7FF#AA"), "unknown COB-ID 0x7FF: AA");
        assert_eq!(d("580#00"), "unknown COB-ID 0x580: 00");
        assert_eq!(d("700#00"), "unknown COB-ID 0x700: 00");
    }
}
