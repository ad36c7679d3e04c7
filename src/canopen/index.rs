//! Every CiA 301 and CiA 402 object index the code uses, named once, with where the
//! specification defines it. Code names the objects (`index::CONTROLWORD`, not `0x6040`); raw
//! indices remain only here, in tests, and in data files and messages for people.
//! `tests/object_index_names.rs` keeps it so.
//!
//! CiA 301 sections are those of CiA 301 v4.2.0 (§7.5.2: the communication profile area's
//! objects). CiA 402 objects are in CiA 402-2 (IEC 61800-7-201), cited by the clause that
//! defines each (its number differs between editions, so by its title).
//!
//! EMCY codes share the number ranges (0x1000 generic error, 0x6320 parameter error, ...) but
//! are not indices: they are named in [`super::emcy::code`].

use std::ops::RangeInclusive;

// --- CiA 301: communication profile area (0x1000–0x1FFF) -----------------------------------

/// The communication profile area (CiA 301 §7.4.1, object dictionary structure): the indices
/// a reset of communication restores.
pub const COMMUNICATION_AREA: RangeInclusive<u16> = 0x1000..=0x1FFF;
/// Device type (UNSIGNED32): the profile number (402) and its additional information
/// (CiA 301 §7.5.2.1).
pub const DEVICE_TYPE: u16 = 0x1000;
/// Error register (UNSIGNED8), also the second byte of every EMCY (CiA 301 §7.5.2.2).
pub const ERROR_REGISTER: u16 = 0x1001;
/// Pre-defined error field (ARRAY UNSIGNED32): sub 0 the count, sub 1 the newest error
/// (CiA 301 §7.5.2.4).
pub const PREDEFINED_ERROR_FIELD: u16 = 0x1003;
/// COB-ID SYNC (UNSIGNED32) (CiA 301 §7.5.2.5).
pub const COB_ID_SYNC: u16 = 0x1005;
/// Communication cycle period (UNSIGNED32), µs: the SYNC period (CiA 301 §7.5.2.6).
pub const COMMUNICATION_CYCLE_PERIOD: u16 = 0x1006;
/// Synchronous window length (UNSIGNED32), µs: synchronous PDOs are valid only inside it
/// (CiA 301 §7.5.2.7).
pub const SYNC_WINDOW_LENGTH: u16 = 0x1007;
/// Manufacturer device name (VISIBLE_STRING) (CiA 301 §7.5.2.8).
pub const DEVICE_NAME: u16 = 0x1008;
/// COB-ID EMCY (UNSIGNED32) (CiA 301 §7.5.2.17).
pub const COB_ID_EMCY: u16 = 0x1014;
/// Inhibit time EMCY (UNSIGNED16), 100 µs units (CiA 301 §7.5.2.18).
pub const INHIBIT_TIME_EMCY: u16 = 0x1015;
/// Consumer heartbeat time (ARRAY UNSIGNED32): per sub, node id (bits 16–23) and time in ms
/// (bits 0–15); 0 switches the entry off (CiA 301 §7.5.2.19).
pub const CONSUMER_HEARTBEAT_TIME: u16 = 0x1016;
/// Producer heartbeat time (UNSIGNED16), ms; 0 switches it off (CiA 301 §7.5.2.20).
pub const PRODUCER_HEARTBEAT_TIME: u16 = 0x1017;
/// Identity object (RECORD): sub 1 vendor-ID, 2 product code, 3 revision, 4 serial number
/// (CiA 301 §7.5.2.21).
pub const IDENTITY: u16 = 0x1018;
/// Synchronous counter overflow value (UNSIGNED8): 0, a SYNC without counter
/// (CiA 301 §7.5.2.22).
pub const SYNC_COUNTER_OVERFLOW: u16 = 0x1019;
/// Error behaviour object (ARRAY UNSIGNED8): sub 1, the reaction to a communication error
/// (0 pre-operational, 1 no change, 2 stopped) (CiA 301 §7.5.2.32).
pub const ERROR_BEHAVIOUR: u16 = 0x1029;
/// RPDO communication parameter of RPDO1 (RECORD); RPDO n is at + n − 1
/// (CiA 301 §7.5.2.35).
pub const RPDO_COMMUNICATION: u16 = 0x1400;
/// RPDO mapping parameter of RPDO1 (RECORD); RPDO n is at + n − 1 (CiA 301 §7.5.2.36).
pub const RPDO_MAPPING: u16 = 0x1600;
/// TPDO communication parameter of TPDO1 (RECORD); TPDO n is at + n − 1
/// (CiA 301 §7.5.2.37).
pub const TPDO_COMMUNICATION: u16 = 0x1800;
/// TPDO mapping parameter of TPDO1 (RECORD); TPDO n is at + n − 1 (CiA 301 §7.5.2.38).
pub const TPDO_MAPPING: u16 = 0x1A00;
/// The RPDO mapping parameters of all 512 RPDOs (CiA 301 §7.5.2.36).
pub const RPDO_MAPPING_AREA: RangeInclusive<u16> = 0x1600..=0x17FF;
/// The TPDO mapping parameters of all 512 TPDOs (CiA 301 §7.5.2.38).
pub const TPDO_MAPPING_AREA: RangeInclusive<u16> = 0x1A00..=0x1BFF;
/// The last PDO parameter index: the PDO communication and mapping parameters are
/// [`RPDO_COMMUNICATION`]`..=`this (CiA 301 §7.5.2.35–38).
pub const PDO_PARAMETERS_LAST: u16 = 0x1BFF;

// --- CiA 402: drive profile (0x6000–0x67FF) ------------------------------------------------

/// Abort connection option code (INT16): the reaction to a lost heartbeat or guarding
/// (1 fault, 2 disable voltage, 3 quick stop) (CiA 402-2, common entries: abort connection
/// option code).
pub const ABORT_CONNECTION_OPTION: u16 = 0x6007;
/// Error code (UNSIGNED16): the last error, coded as EMCY codes (CiA 402-2, common entries:
/// error code).
pub const ERROR_CODE: u16 = 0x603F;
/// Controlword (UNSIGNED16) (CiA 402-2, device control: controlword).
pub const CONTROLWORD: u16 = 0x6040;
/// Statusword (UNSIGNED16) (CiA 402-2, device control: statusword).
pub const STATUSWORD: u16 = 0x6041;
/// Quick stop option code (INT16), 0..=8 (CiA 402-2, device control: quick stop option code).
pub const QUICK_STOP_OPTION: u16 = 0x605A;
/// Modes of operation (INT8) (CiA 402-2, device control: modes of operation).
pub const MODES_OF_OPERATION: u16 = 0x6060;
/// Modes of operation display (INT8): a mode is active only once this echoes 0x6060
/// (CiA 402-2, device control: modes of operation display).
pub const MODES_DISPLAY: u16 = 0x6061;
/// Position demand value (INT32), position units (CiA 402-2, position control function).
pub const POSITION_DEMAND: u16 = 0x6062;
/// Position actual value (INT32), position units (CiA 402-2, position control function).
pub const POSITION_ACTUAL: u16 = 0x6064;
/// Following error window (UNSIGNED32), position units (CiA 402-2, position control function).
pub const FOLLOWING_ERROR_WINDOW: u16 = 0x6065;
/// Following error time out (UNSIGNED16), ms (CiA 402-2, position control function).
pub const FOLLOWING_ERROR_TIMEOUT: u16 = 0x6066;
/// Position window (UNSIGNED32), position units (CiA 402-2, position control function).
pub const POSITION_WINDOW: u16 = 0x6067;
/// Velocity actual value (INT32), velocity units (CiA 402-2, profile velocity mode).
pub const VELOCITY_ACTUAL: u16 = 0x606C;
/// Target position (INT32): the CSP setpoint, sent every SYNC (CiA 402-2, profile position
/// mode; cyclic synchronous position mode).
pub const TARGET_POSITION: u16 = 0x607A;
/// Home offset (INT32), position units: the position actual value the drive reports at the
/// home position once homing is attained (CiA 402-2, homing mode: home offset).
pub const HOME_OFFSET: u16 = 0x607C;
/// Software position limit (ARRAY INT32): sub 1 minimum, sub 2 maximum (CiA 402-2, profile
/// position mode).
pub const SOFTWARE_POSITION_LIMIT: u16 = 0x607D;
/// Max profile velocity (UNSIGNED32), velocity units (CiA 402-2, profile position mode).
pub const MAX_PROFILE_VELOCITY: u16 = 0x607F;
/// Profile acceleration (UNSIGNED32), acceleration units (CiA 402-2, profile position mode).
pub const PROFILE_ACCELERATION: u16 = 0x6083;
/// Profile deceleration (UNSIGNED32): the slow-down ramp of quick-stop codes 1 and 5
/// (CiA 402-2, profile position mode).
pub const PROFILE_DECELERATION: u16 = 0x6084;
/// Quick stop deceleration (UNSIGNED32): the ramp of quick-stop codes 2 and 6 (CiA 402-2,
/// profile position mode).
pub const QUICK_STOP_DECELERATION: u16 = 0x6085;
/// Position encoder resolution (ARRAY UNSIGNED32) (CiA 402-2, factor group).
pub const POSITION_ENCODER_RESOLUTION: u16 = 0x608F;
/// Gear ratio (ARRAY UNSIGNED32) (CiA 402-2, factor group).
pub const GEAR_RATIO: u16 = 0x6091;
/// Feed constant (ARRAY UNSIGNED32) (CiA 402-2, factor group).
pub const FEED_CONSTANT: u16 = 0x6092;
/// Homing method (INTEGER8): 17/18 limit switches, 19–22 home switch, 35/37 the current
/// position (CiA 402-2, homing mode: homing method).
pub const HOMING_METHOD: u16 = 0x6098;
/// Homing speeds (ARRAY UNSIGNED32), velocity units: sub 1 the search for the switch, sub 2
/// the search for zero (CiA 402-2, homing mode: homing speeds).
pub const HOMING_SPEEDS: u16 = 0x6099;
/// Homing acceleration (UNSIGNED32), acceleration units: the ramp of every homing motion
/// (CiA 402-2, homing mode: homing acceleration).
pub const HOMING_ACCELERATION: u16 = 0x609A;
/// Interpolation sub mode select (INT16): 0 linear (CiA 402-2, interpolated position mode).
pub const IP_SUBMODE: u16 = 0x60C0;
/// Interpolation data record (ARRAY): sub 1 the INT32 position setpoint (CiA 402-2,
/// interpolated position mode).
pub const IP_DATA_RECORD: u16 = 0x60C1;
/// Interpolation time period (RECORD): sub 1 value (UNSIGNED8), sub 2 index (INT8); period =
/// value × 10^index s; must equal 0x1006 (CiA 402-2, interpolated position mode).
pub const IP_TIME_PERIOD: u16 = 0x60C2;
/// Interpolation data configuration (RECORD) (CiA 402-2, interpolated position mode).
pub const IP_DATA_CONFIG: u16 = 0x60C4;
/// Max acceleration (UNSIGNED32), acceleration units (CiA 402-2, profile position mode).
pub const MAX_ACCELERATION: u16 = 0x60C5;
/// Supported homing methods (ARRAY INTEGER8): sub 0 the count, then one method per sub
/// (CiA 402-2, homing mode: supported homing methods).
pub const SUPPORTED_HOMING_METHODS: u16 = 0x60E3;
/// Following error actual value (INT32), position units (CiA 402-2, position control
/// function).
pub const FOLLOWING_ERROR_ACTUAL: u16 = 0x60F4;
/// Position demand value, internal (INT32), increments (CiA 402-2, position control function).
pub const POSITION_DEMAND_INTERNAL: u16 = 0x60FC;
/// Target velocity (INT32), velocity units (CiA 402-2, profile velocity mode).
pub const TARGET_VELOCITY: u16 = 0x60FF;
/// Supported drive modes (UNSIGNED32), one bit per mode (CiA 402-2, common entries:
/// supported drive modes).
pub const SUPPORTED_MODES: u16 = 0x6502;
