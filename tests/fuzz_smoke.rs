//! Short seeded runs of every fuzz target (`fuzz/`, `src/fuzzing/`): a few thousand inputs
//! mutated from the repository's own files, so that a parser that panics on a malformed input
//! fails the ordinary test suite, not only a fuzzing session. The long runs are
//! `cargo fuzz run NAME` (see `fuzz/Cargo.toml`).

use canmotion::fuzzing::{self, run_seeded};
use std::path::Path;

/// Every file under `dir` (relative to the crate) whose name ends in one of `exts`.
fn seeds(dir: &str, exts: &[&str]) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join(dir);
    let mut stack = vec![root];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        let mut entries: Vec<_> = rd.flatten().map(|e| e.path()).collect();
        entries.sort();
        for p in entries {
            if p.is_dir() {
                stack.push(p);
            } else if exts.iter().any(|e| p.to_string_lossy().ends_with(e)) {
                out.push(std::fs::read(&p).expect("seed file"));
            }
        }
    }
    assert!(!out.is_empty(), "no seed files under {dir}");
    out
}

#[test]
fn gcode_programs() {
    let mut s = seeds("tests/programs", &[".ngc"]);
    s.extend(seeds("examples", &[".ngc"]));
    let s: Vec<&[u8]> = s.iter().map(Vec::as_slice).collect();
    run_seeded(&s, 1500, 1, fuzzing::gcode::program);
}

#[test]
fn canned_cycle_programs() {
    let s = seeds("tests/programs", &["cycles_g17.ngc", "cycles_g18_g19.ngc"]);
    let s: Vec<&[u8]> = s.iter().map(Vec::as_slice).collect();
    run_seeded(&s, 3000, 6, fuzzing::cycles::program);
}

#[test]
fn subroutine_programs() {
    let mut s = seeds("tests/programs", &["subroutines.ngc", "m99_restart.ngc"]);
    s.extend(seeds("tests/programs/subs", &[".ngc"]));
    // A main program, a 0 byte, then the text of the subroutine file f.ngc.
    s.push(b"G21\no<f> call [3]\nM98 P100 L2\nM30\nO100\nG0 X1\nM99\n\0o<f> sub\nG1 X#1 F60\no<f> endsub\n".to_vec());
    let s: Vec<&[u8]> = s.iter().map(Vec::as_slice).collect();
    run_seeded(&s, 2000, 7, fuzzing::subroutines::program);
}

#[test]
fn control_lines() {
    let s = seeds("tests/control_lines", &[".txt"]);
    let s: Vec<&[u8]> = s.iter().map(Vec::as_slice).collect();
    run_seeded(&s, 4000, 2, fuzzing::control::lines);
}

/// A small EDS like the ones `tests/eds_import.rs` builds: identity, a VAR, an ARRAY with
/// sub-objects, a DCF commissioning section, `$NODEID` defaults.
const EDS_SEED: &str = "\
[FileInfo]
FileName=seed.eds
[DeviceInfo]
VendorNumber=0x1234
ProductNumber=2
[DeviceComissioning]
NodeID=3
[MandatoryObjects]
SupportedObjects=2
1=0x1000
2=0x1018
[OptionalObjects]
SupportedObjects=1
1=0x1400
[1000]
ParameterName=Device type
ObjectType=0x7
DataType=0x0007
AccessType=ro
DefaultValue=0x00020192
PDOMapping=0
[1018]
ParameterName=Identity
ObjectType=0x9
SubNumber=2
[1018sub0]
ParameterName=Highest sub-index
ObjectType=0x7
DataType=0x0005
AccessType=ro
DefaultValue=1
[1018sub1]
ParameterName=Vendor-ID
ObjectType=0x7
DataType=0x0007
AccessType=ro
DefaultValue=0x1234
[1400]
ParameterName=RPDO1 communication
ObjectType=0x9
SubNumber=2
[1400sub0]
ParameterName=Highest sub-index
ObjectType=0x7
DataType=0x0005
AccessType=ro
DefaultValue=2
[1400sub1]
ParameterName=COB-ID
ObjectType=0x7
DataType=0x0007
AccessType=rw
DefaultValue=$NODEID+0x200
[1400sub2]
ParameterName=Transmission type
ObjectType=0x7
DataType=0x0005
AccessType=rw
DefaultValue=1
LowLimit=0
HighLimit=0xFF
[6040]
ParameterName=Controlword
ObjectType=0x7
DataType=0x0006
AccessType=rww
DefaultValue=0
PDOMapping=1
";

#[test]
fn eds_files() {
    let mut s: Vec<Vec<u8>> = vec![EDS_SEED.as_bytes().to_vec()];
    let corpus = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus/eds");
    if corpus.is_dir() {
        s.extend(seeds(
            "../shared/corpus/eds",
            &[".eds", ".dcf", ".EDS", ".DCF"],
        ));
    } else {
        eprintln!(
            "eds_files: no EDS corpus at {} (third-party files, not in the repository): seeded from the built-in EDS only",
            corpus.display()
        );
    }
    let s: Vec<&[u8]> = s.iter().map(Vec::as_slice).collect();
    run_seeded(&s, 1500, 2, fuzzing::eds::import);
}

#[test]
fn candump_lines() {
    let log: &[u8] = b"\
(1700000000.123456) vcan0 181#3716E8030000
(1700000000.124001) vcan0 080#
(1700000000.200000) vcan0 701#R
(1700000000.200100) vcan0 701#R1
(1700000000.300000) can0 601#40.00.10.00.00.00.00.00 R
(1700000000.300500) can0 581#4300100092010200 T
# a comment

(1700000000.400000) vcan0 20000040#0000000000000000
(1700000000.400001) vcan0 20000204#0030000000008000
(1700000000.5) vcan0 000#0100
";
    let single: Vec<&[u8]> = log.split(|b| *b == b'\n').collect();
    let mut s = vec![log];
    s.extend(single.iter().filter(|l| !l.is_empty()));
    run_seeded(&s, 4000, 3, fuzzing::candump::log);
}

#[test]
fn machine_files() {
    let s = seeds("dictionaries/machines", &[".toml"]);
    let s: Vec<&[u8]> = s.iter().map(Vec::as_slice).collect();
    run_seeded(&s, 3000, 2, fuzzing::machine::machine_file);
}
