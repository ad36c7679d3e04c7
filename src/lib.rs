//! # canmotion: a CAN-bus motion gateway
//!
//! canmotion reads a G-code program, plans its motion, interpolates one position per axis every
//! cycle and streams those setpoints to CiA 402 servo drives as CANopen PDOs on SYNC, while it
//! watches every drive's state, position and faults.
//!
//! ## One move, from a G-code line to a CAN frame
//!
//! Take `G1 X50 F1200` on line 5 of a program, on the demo machine (X on node 1, 1000 counts/mm,
//! interpolated position mode, 4 ms cycle).
//!
//! 1. [`gcode`] reads the program line by line ([`gcode::Interpreter`], bounded memory) and
//!    the whole of it is interpreted before anything moves; the line becomes a
//!    [`gcode::Element`], a straight move with absolute start and end points in machine
//!    millimetres and a feed of 20 mm/s. An error names `file:line:col`.
//! 2. [`compensation::Compensator`] wraps the interpreter's stream
//!    ([`gateway::interpret_program`] for `run`, [`offline::plan_stream`] for `plan`) and moves
//!    elements under G41/G42 to the tool centre (C-type cutter radius compensation, looking
//!    ahead to the next element in the plane); under G40, as here, the element passes through
//!    unchanged.
//! 3. [`gateway::plan_program`] checks the target against the axes' travel, then
//!    [`planner::plan_with`] (the look-ahead of [`planner::Planner`], configured by the
//!    machine's `[planner]` table) turns the element into a [`planner::Segment`]: a speed
//!    profile (trapezoid or S-curve) from its start to its end speed, limited by the feed and by
//!    each axis's limits projected on the move's direction; this single move starts and ends at
//!    rest, and a junction with a next move would keep the speed its velocity jump allows.
//!    On a machine with auxiliary axes (a rotary A, or U V W) the element also carries their
//!    start and end ([`gcode::AuxMove`]), linear in its path, and [`planner::aux_axes`] caps
//!    the profile so that each of them keeps its own limits too.
//! 4. [`interpolator::Interpolator::update`] samples the plan once per cycle, Ruckig-style: no
//!    allocation, no blocking; the last sample is the end point, exactly (the auxiliary axes'
//!    samples come with it: [`interpolator::Interpolator::aux`]). An axis with a
//!    `filter` in the machine file passes its samples through [`interpolator::filter::AxisFilter`]
//!    (moving average or first-order lag after interpolation), which ends exactly there too.
//! 5. [`master::cyclic::CyclicMaster::cycle`], on the cyclic thread ([`rt`]: absolute deadlines,
//!    SCHED_FIFO where permitted; no allocation, even when it stops on a
//!    [`master::alarm::Alarm`]), converts the sample to counts (50 mm → 50000), checks it
//!    against the travel and the largest step a cycle allows, and packs it with the controlword
//!    into the axis's RPDO as the machine file maps it (`0x60400010, 0x60C10120`: the objects
//!    [`canopen::index`] names):
//!    [`bus::Frame`] `201#1F0050C30000`, then the SYNC frame `080#`.
//! 6. [`bus`] sends both on the bus: SocketCAN (`vcan0`, `can0`) or the in-process bus. The
//!    drive ([`sim`] in tests and the demo, a real servo otherwise) latches the setpoint at SYNC,
//!    interpolates towards it over the period and answers with its TPDO `181#3716` followed by the position
//!    (statusword, position actual), which the next cycle reads back for the following error.
//!
//! Before the first cycle, [`master::startup`] (a sans-I/O state machine that
//! [`gateway::startup`] drives on the bus) has used SDO ([`canopen`]: the codecs of canopen-rs,
//! our SDO client, server and abort tables) to check each drive's identity,
//! read its position actual (every axis inside its travel before anything is written), write the
//! machine file's settings, remap the PDOs, set 0x60C2 to the SYNC period and the
//! mode; [`cia402`] then walks each drive to Operation enabled through the RPDO's controlword,
//! and IP mode starts only once statusword bit 12 answers controlword bit 4 (bumpless: the
//! first setpoint is position actual).
//!
//! ## Layers
//!
//! Data flows one way: `gcode → compensation → planner → interpolator → master::cyclic →
//! canopen/cia402 → bus`. Only [`bus`], [`rt`], the runners in [`sim::runner`] and
//! [`gateway`], and the command line touch sockets, threads or the wall clock; everything else
//! takes time as an argument.
//!
//! Imports go down only. The layers, lowest first (a module may import its own layer and the
//! ones before it; `tests/layers.rs` holds the same list and fails on an import of a higher
//! layer):
//!
//! 1. [`files`]: how the command line and the loaders open their inputs (regular files only,
//!    bounded) and write their outputs (atomically, or in place through a symlink or to a
//!    device);
//! 2. [`bus`]: frames, SocketCAN and the in-process bus;
//! 3. [`canopen`]: codecs, SDO, EMCY, the named object indices and the drive dictionary model
//!    ([`canopen::dictionary`]);
//! 4. [`cia402`]: the drive state machine;
//! 5. [`gcode`]: the interpreter ([`gcode::Interpreter`]) and the tool table
//!    ([`gcode::ToolTable`]);
//! 6. [`compensation`];
//! 7. [`planner`];
//! 8. [`interpolator`];
//! 9. [`config`]: machine files (which configure the layers above), and the loading of drive
//!    dictionaries and tool tables;
//! 10. [`eds`]: EDS/DCF import into a drive dictionary;
//! 11. [`master`]: the sans-I/O CANopen master (start-up and the orderly end, the cyclic
//!     master, its alarms, supervision), fed `(now, frame)` by the drivers in [`gateway`] and by
//!     virtual-clock tests;
//! 12. [`rt`]: the cyclic thread's timing;
//! 13. [`sim`]: the simulated drive;
//! 14. [`gateway`]: the drivers of the master (the real-time thread, SocketCAN or the
//!     in-process bus, tokio), resume, the control socket;
//! 15. [`plot`] and [`optimize`];
//! 16. [`offline`], the `plan` command;
//! 17. [`commands`]: the bus utilities (`scan`, `sdo`, `nmt`, `reset`, `monitor`, `candump`),
//!     then `main.rs`, the command line.

pub mod bus;
pub mod canopen;
pub mod cia402;
pub mod commands;
pub mod compensation;
pub mod config;
pub mod eds;
pub mod files;
#[doc(hidden)]
pub mod fuzzing;
pub mod gateway;
pub mod gcode;
pub mod interpolator;
pub mod master;
pub mod offline;
pub mod optimize;
pub mod planner;
pub mod plot;
pub mod rt;
pub mod sim;
