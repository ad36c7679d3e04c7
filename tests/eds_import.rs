//! EDS/DCF import (`canmotion dict import`): every file of the corpus imports and loads, spot
//! checks per file, line-numbered errors on malformed input, an imported dictionary driving the
//! simulated drive, and the command line end to end.
//!
//! The corpus (`../shared/corpus/eds`, third-party files) is read at test time; the tests that
//! need it say so and pass when it is absent.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use canmotion::bus::Frame;
use canmotion::config::DriveDictionary;
use canmotion::config::dictionary::DefaultValue;
use canmotion::eds::{self, EdsError, ImportOptions, Imported};
use canmotion::sim::SimDrive;
use canopen_rs::{DataType, Value};

fn corpus() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus/eds");
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!(
            "skipped: no EDS corpus at {} (third-party files, not in the repository)",
            dir.display()
        );
        None
    }
}

fn import(dir: &Path, name: &str, opts: ImportOptions) -> Imported {
    let path = dir.join(name);
    eds::import_file(&path, &opts).unwrap_or_else(|e| panic!("{e}"))
}

fn fixed(d: &DriveDictionary, index: u16, sub: u8) -> Value {
    match &d
        .sub(index, sub)
        .unwrap_or_else(|| panic!("0x{index:04X}:{sub}"))
        .default
    {
        DefaultValue::Fixed(v) => *v,
        other => panic!("0x{index:04X}:{sub}: {other:?}"),
    }
}

fn relative(d: &DriveDictionary, index: u16, sub: u8) -> u64 {
    match &d.sub(index, sub).unwrap().default {
        DefaultValue::NodeIdPlus(off) => *off,
        other => panic!("0x{index:04X}:{sub}: {other:?}"),
    }
}

#[test]
fn every_corpus_file_imports_and_loads() {
    let Some(dir) = corpus() else { return };
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("eds") || e.eq_ignore_ascii_case("dcf"))
        })
        .collect();
    files.sort();
    assert!(!files.is_empty());
    for path in files {
        let imported =
            eds::import_file(&path, &ImportOptions::default()).unwrap_or_else(|e| panic!("{e}"));
        let d = DriveDictionary::parse(&path.with_extension("toml"), &imported.toml)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_eq!(d.objects.len(), imported.objects);
        assert!(d.objects.contains_key(&0x1000) && d.objects.contains_key(&0x1018));
        // Every default the loader holds can be instantiated for any node.
        for node in [1u8, 127] {
            for o in d.objects.values() {
                for s in o.subs.values() {
                    let _ = d.default_for(s, node);
                }
            }
        }
        // A header says where it came from.
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        assert!(
            imported
                .toml
                .starts_with("# Drive dictionary imported from the ")
                && imported.toml.lines().take(3).any(|l| l.contains(&name)),
            "{}",
            &imported.toml[..200]
        );
        println!(
            "{name}: {} objects, {} entries, {} skipped, {} notes",
            imported.objects,
            imported.entries,
            imported.skipped,
            imported.notes.len()
        );
    }
}

#[test]
fn ros2_cia402_slave_has_the_drive_objects_and_its_identity() {
    let Some(dir) = corpus() else { return };
    let i = import(
        &dir,
        "ros2_canopen-cia402_slave.eds",
        ImportOptions::default(),
    );
    let d = &i.dictionary;
    for (index, t, access, pdo) in [
        (
            0x6040,
            DataType::Unsigned16,
            canmotion::config::Access::Rw,
            true,
        ),
        (
            0x6041,
            DataType::Unsigned16,
            canmotion::config::Access::Ro,
            true,
        ),
        (
            0x6064,
            DataType::Integer32,
            canmotion::config::Access::Ro,
            true,
        ),
        (
            0x607A,
            DataType::Integer32,
            canmotion::config::Access::Rw,
            true,
        ),
        (
            0x6060,
            DataType::Integer8,
            canmotion::config::Access::Rw,
            true,
        ),
    ] {
        let s = d.sub(index, 0).unwrap();
        assert_eq!(
            (s.data_type, s.access, s.pdo),
            (t, access, pdo),
            "0x{index:04X}"
        );
    }
    let id = d.identity;
    assert_eq!(
        (id.vendor_id, id.product_code, id.revision, id.device_type),
        (0x555, 0x1, 0x0, 0xFFFF_0192)
    );
    assert_eq!(d.name, "ROS-Industrial CIA402VTD");
    assert_eq!(relative(d, 0x1400, 1), 0x4000_0200);
    assert_eq!(relative(d, 0x1014, 0), 0x80);
    assert_eq!(fixed(d, 0x1A00, 1), Value::Unsigned32(0x6041_0010));
    assert_eq!(fixed(d, 0x607D, 1), Value::Integer32(i32::MIN));
    assert_eq!(fixed(d, 0x60C2, 2), Value::Integer8(-2));
    assert_eq!(fixed(d, 0x6067, 0), Value::Unsigned32(0xFFFF_FFFF));
    assert!(
        i.toml
            .contains("access = \"rw\"                # rww in the EDS")
    );
    assert!(!i.dcf && i.node.is_none());
    // With a node id, $NODEID is resolved.
    let i = import(
        &dir,
        "ros2_canopen-cia402_slave.eds",
        ImportOptions {
            node: Some(3),
            ..Default::default()
        },
    );
    assert_eq!(
        fixed(&i.dictionary, 0x1400, 1),
        Value::Unsigned32(0x4000_0203)
    );
    assert!(i.toml.contains("# $NODEID+0x40000200 in the EDS"));
}

#[test]
fn dcf_parameter_values_win_over_defaults() {
    let Some(dir) = corpus() else { return };
    let i = import(&dir, "ros2_canopen-prbt_0_1.dcf", ImportOptions::default());
    let d = &i.dictionary;
    assert!(i.dcf);
    // [1600sub2] DefaultValue=0x60c10120, ParameterValue=0x60420010.
    assert_eq!(fixed(d, 0x1600, 2), Value::Unsigned32(0x6042_0010));
    // [1600sub3] has only a ParameterValue.
    assert_eq!(fixed(d, 0x1600, 3), Value::Unsigned32(0x60C1_0120));
    assert_eq!(fixed(d, 0x1600, 0), Value::Unsigned8(3));
    assert_eq!(fixed(d, 0x1400, 2), Value::Unsigned8(1));
    assert_eq!(fixed(d, 0x1017, 0), Value::Unsigned16(100));
    assert_eq!(fixed(d, 0x6060, 0), Value::Integer8(7));
    assert_eq!(fixed(d, 0x1A00, 2), Value::Unsigned32(0x6061_0008));
    // "$NodeID + 0x200" (any case, spaces) and ParameterValue=$NODEID+0x200.
    assert_eq!(relative(d, 0x1400, 1), 0x200);
    assert!(i.toml.contains("ParameterValue; DefaultValue 0x60c10120"));
    // No identity anywhere in this DCF: zeros, said in the header.
    assert_eq!(d.identity.vendor_id, 0);
    assert!(
        i.toml
            .contains("0x1018:1 (Vendor-ID) has no default and [DeviceInfo] no VendorNumber")
    );
    // A record without sub 0 stays as the DCF has it.
    assert!(d.sub(0x20A0, 7).is_some() && d.sub(0x20A0, 0).is_none());
    // --node resolves the ParameterValues.
    let i = import(
        &dir,
        "ros2_canopen-prbt_0_1.dcf",
        ImportOptions {
            node: Some(9),
            ..Default::default()
        },
    );
    assert_eq!(fixed(&i.dictionary, 0x1800, 1), Value::Unsigned32(0x189));
}

#[test]
fn python_canopen_sample_odd_cases() {
    let Some(dir) = corpus() else { return };
    let i = import(&dir, "python-canopen-sample.eds", ImportOptions::default());
    let d = &i.dictionary;
    // [DeviceComissioning] NodeID=0x10 resolves $NODEID when --node is not given.
    assert!(i.dcf);
    assert_eq!(i.node, Some(0x10));
    assert_eq!(fixed(d, 0x1400, 1), Value::Unsigned32(512 + 0x10));
    assert_eq!(fixed(d, 0x1403, 1), Value::Unsigned32(1280 + 0x10)); // "1280+$NODEID"
    let with_node = import(
        &dir,
        "python-canopen-sample.eds",
        ImportOptions {
            node: Some(2),
            ..Default::default()
        },
    );
    assert_eq!(
        fixed(&with_node.dictionary, 0x1800, 1),
        Value::Unsigned32(384 + 2)
    );
    // Compact arrays: sub 0 is the count, names from [3004Name].
    let o = &d.objects[&0x3004];
    assert_eq!(o.subs.len(), 4);
    assert_eq!(fixed(d, 0x3004, 0), Value::Unsigned8(3));
    assert_eq!(o.subs[&2].name, "Sensor Status 2");
    assert_eq!(fixed(d, 0x3004, 3), Value::Unsigned16(3));
    let o = &d.objects[&0x3006];
    assert_eq!(o.subs.len(), 25);
    assert_eq!(o.subs[&24].data_type, DataType::Real32);
    // Identity: 0x1018:1 has ParameterValue=1 = VendorNumber; sub 3 is missing and added.
    assert_eq!(d.identity.vendor_id, 1);
    assert!(d.sub(0x1018, 3).is_some());
    // Missing sub-indices of 0x1003 stay missing.
    assert!(d.sub(0x1003, 2).is_none() && d.sub(0x1003, 3).is_some());
    // Limits: hex limits of a signed type are two's complement; a missing default moves into
    // the range.
    let s = d.sub(0x3030, 0).unwrap();
    assert_eq!((s.min, s.max), (Some(f64::from(i32::MIN)), Some(-1.0)));
    assert_eq!(fixed(d, 0x3030, 0), Value::Integer32(-1));
    assert_eq!(fixed(d, 0x3021, 0), Value::Unsigned8(2));
    let s = d.sub(0x3040, 0).unwrap();
    assert_eq!((s.min, s.max), (Some(-10.0), Some(10.0)));
    assert_eq!(d.sub(0x3002, 0).unwrap().min, Some(4.5));
    assert_eq!(d.sub(0x3050, 1).unwrap().unit.as_deref(), Some("mV"));
    // Skipped: a manufacturer data type, an array without sub-entries.
    assert!(!d.objects.contains_key(&0x2020) && !d.objects.contains_key(&0x3003));
    assert_eq!(i.skipped, 2);
    assert!(
        i.toml
            .contains("DataType 0x0040 is not a CiA 301 basic type: skipped")
    );
    assert!(i.toml.contains("| Don't panic |"));
}

#[test]
fn python_canopen_datatypes_cover_every_type() {
    let Some(dir) = corpus() else { return };
    let i = import(
        &dir,
        "python-canopen-datatypes.eds",
        ImportOptions::default(),
    );
    let d = &i.dictionary;
    let t = |index| d.sub(index, 0).unwrap().data_type;
    for (index, want) in [
        (0x2001, DataType::Boolean),
        (0x2002, DataType::Integer8),
        (0x2003, DataType::Integer16),
        (0x2004, DataType::Integer32),
        (0x2005, DataType::Unsigned8),
        (0x2006, DataType::Unsigned16),
        (0x2007, DataType::Unsigned32),
        (0x2008, DataType::Real32),
        (0x2009, DataType::VisibleString),
        (0x200A, DataType::OctetString),
        (0x200B, DataType::VisibleString), // UNICODE_STRING
        (0x200F, DataType::Domain),
        (0x2010, DataType::Integer32), // INTEGER24
        (0x2011, DataType::Real64),
        (0x2012, DataType::Integer64), // INTEGER40
        (0x2013, DataType::Integer64), // INTEGER48
        (0x2014, DataType::Integer64), // INTEGER56
        (0x2015, DataType::Integer64),
        (0x2016, DataType::Unsigned32), // UNSIGNED24
        (0x2018, DataType::Unsigned64), // UNSIGNED40
        (0x2019, DataType::Unsigned64), // UNSIGNED48
        (0x201A, DataType::Unsigned64), // UNSIGNED56
        (0x201B, DataType::Unsigned64),
    ] {
        assert_eq!(t(index), want, "0x{index:04X}");
    }
    assert_eq!(fixed(d, 0x2002, 0), Value::Integer8(12));
    assert_eq!(fixed(d, 0x2008, 0), Value::Real32(1.2));
    assert_eq!(fixed(d, 0x2011, 0), Value::Real64(1.6));
    assert_eq!(fixed(d, 0x2010, 0), Value::Integer32(-1));
    assert_eq!(fixed(d, 0x2015, 0), Value::Integer64(-64));
    assert_eq!(fixed(d, 0x201B, 0), Value::Unsigned64(64));
    assert_eq!(
        d.sub(0x200B, 0).unwrap().default,
        DefaultValue::Bytes("abc✓".as_bytes().to_vec())
    );
    // Odd widths keep their range and lose PDO mapping; fixed widths keep it.
    let s = d.sub(0x2010, 0).unwrap();
    assert_eq!(
        (s.min, s.max, s.pdo),
        (Some(-8_388_608.0), Some(8_388_607.0), false)
    );
    let s = d.sub(0x2016, 0).unwrap();
    assert_eq!((s.max, s.pdo), (Some(16_777_215.0), false));
    assert!(d.sub(0x2004, 0).unwrap().pdo && d.sub(0x2011, 0).unwrap().pdo);
    // Variable-length types cannot be PDO-mapped in our format.
    assert!(!d.sub(0x2009, 0).unwrap().pdo);
    assert!(i.toml.contains("INTEGER24 in the EDS: widened to 32 bits"));
    // No 0x1000 in this EDS: added.
    assert_eq!(d.identity.device_type, 0);
    assert!(i.toml.contains("the EDS has no object 0x1000: added"));
}

#[test]
fn e35_identity_conflict_device_info_wins_or_is_an_error() {
    let Some(dir) = corpus() else { return };
    let i = import(&dir, "python-canopen-e35.eds", ImportOptions::default());
    let id = i.dictionary.identity;
    // [DeviceInfo] VendorNumber=101 ProductNumber=25 RevisionNumber=295; 0x1018 says 0xFF 1 1.
    assert_eq!(
        (id.vendor_id, id.product_code, id.revision, id.device_type),
        (101, 25, 295, 0x20192)
    );
    assert!(i.toml.contains(
        "EDS line 89: 0x1018:1 (Vendor-ID) default 0x000000FF contradicts [DeviceInfo] VendorNumber"
    ));
    let e = eds::import_file(
        &dir.join("python-canopen-e35.eds"),
        &ImportOptions {
            strict_identity: true,
            ..Default::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.ends_with(
            "python-canopen-e35.eds:89: 0x1018:1 (Vendor-ID) default 0x000000FF contradicts [DeviceInfo] VendorNumber 0x00000065 at line 16"
        ),
        "{e}"
    );
    assert!(i.objects > 200);
    // The command line prints the file-level notes.
    assert!(i.summary().contains(
        "note              line 89: 0x1018:1 (Vendor-ID) default 0x000000FF contradicts"
    ));
}

fn malformed(text: &str) -> String {
    match eds::import_str(Path::new("bad.eds"), text, &ImportOptions::default()) {
        Err(e @ EdsError::Line { .. }) => e.to_string(),
        other => panic!("{other:?}"),
    }
}

#[test]
fn malformed_eds_gives_line_numbered_errors() {
    let head = "[DeviceInfo]\nVendorNumber=1\n\n[1000]\nParameterName=Device type\nObjectType=0x7\nDataType=0x0007\nAccessType=ro\nDefaultValue=0\n";
    // Line 10 onwards is the case under test.
    assert_eq!(
        malformed(&format!("{head}[1018sub1]\nParameterName=Vendor\n")),
        "bad.eds:10: sub-object section [1018sub1] without its parent [1018]"
    );
    assert_eq!(
        malformed(&format!(
            "{head}[2000]\nParameterName=x\nObjectType=0x7\nDataType=0x0007\nAccessType=rw\nDefaultValue=12G\n"
        )),
        "bad.eds:15: DefaultValue \"12G\": bad number \"12G\" (expected decimal, 0x hexadecimal or 0 octal)"
    );
    assert_eq!(
        malformed(&format!(
            "{head}[2000]\nParameterName=x\nObjectType=0x7\nAccessType=rw\n"
        )),
        "bad.eds:10: [2000]: missing DataType for a VAR"
    );
    assert_eq!(
        malformed(&format!(
            "{head}[2000]\nParameterName=x\nObjectType=0x7\nDataType=0x0006\nAccessType=rw\nDefaultValue=09\n"
        )),
        "bad.eds:15: DefaultValue \"09\": bad number \"09\" (a leading 0 means octal in CiA 306)"
    );
    assert_eq!(
        malformed(&format!(
            "{head}[2000]\nObjectType=0x7\nDataType=0x7\nAccessType=read\n"
        )),
        "bad.eds:13: AccessType \"read\" is not one of ro wo rw rwr rww const"
    );
    assert_eq!(
        malformed(&format!("{head}[2000]\nObjectType=0x7\nDataType=seven\n")),
        "bad.eds:12: DataType: bad number \"seven\" (expected decimal, 0x hexadecimal or 0 octal)"
    );
    assert_eq!(
        malformed(&format!("{head}[2000]\nObjectType=0x3\n")),
        "bad.eds:11: unknown ObjectType 0x3 (expected 0x7 VAR, 0x8 ARRAY, 0x9 RECORD, 0x2 DOMAIN, 0x5 DEFTYPE, 0x6 DEFSTRUCT)"
    );
    assert_eq!(
        malformed(&format!(
            "{head}[2000]\nObjectType=0x7\nDataType=0x5\nAccessType=ro\nDefaultValue=$NODEID*2\n"
        )),
        "bad.eds:14: DefaultValue \"$NODEID*2\": bad $NODEID expression \"$NODEID*2\" (expected $NODEID+n or n+$NODEID)"
    );
    assert_eq!(
        malformed(&format!("{head}[1000]\n")),
        "bad.eds:10: section [1000] already defined at line 4"
    );
    assert_eq!(
        malformed(&format!("{head}[1018\n")),
        "bad.eds:10: section header without ']': [1018"
    );
    assert_eq!(
        malformed(&format!("{head}DataType\n")),
        "bad.eds:10: expected key=value in [1000], found \"DataType\""
    );
    assert_eq!(
        malformed(&format!("{head}DataType=0x5\n")),
        "bad.eds:10: DataType given twice in [1000] (first at line 7)"
    );
    assert_eq!(
        malformed(&format!(
            "{head}[2000]\nObjectType=0x8\nCompactSubObj=2\nDataType=0x5\nAccessType=ro\n[2000sub1]\n"
        )),
        "bad.eds:15: sub-object section [2000sub1] for 0x2000, which has CompactSubObj=2 (line 12)"
    );
    assert_eq!(
        malformed("[DeviceComissioning]\nNodeID=200\n[1000]\n"),
        "bad.eds:2: NodeID 200 is not a node id (1..127)"
    );
    assert_eq!(
        malformed("NodeID=1\n"),
        "bad.eds:1: \"NodeID=1\" outside any [section]"
    );
}

#[test]
fn an_imported_dictionary_drives_the_simulated_drive() {
    let Some(dir) = corpus() else { return };
    let i = import(
        &dir,
        "ros2_canopen-cia402_slave.eds",
        ImportOptions::default(),
    );
    let node = 5u8;
    let mut drive = SimDrive::new(Arc::new(i.dictionary), node);
    let mut out = Vec::new();
    let mut now = Duration::from_millis(1);

    drive.boot(now, &mut out);
    assert_eq!(out.len(), 1);
    assert_eq!(
        (out[0].id(), out[0].data()),
        (0x700 + u16::from(node), &[0x00][..])
    );

    // SDO upload of 0x1000: the EDS's device type, expedited, 4 bytes.
    let upload = |drive: &mut SimDrive, now, index: u16, sub: u8| {
        let [lo, hi] = index.to_le_bytes();
        let req = Frame::new(0x600 + u16::from(node), &[0x40, lo, hi, sub, 0, 0, 0, 0]).unwrap();
        let mut out = Vec::new();
        drive.handle(now, &req, &mut out);
        assert_eq!(out.len(), 1, "{out:?}");
        assert_eq!(out[0].id(), 0x580 + u16::from(node));
        out[0].data().to_vec()
    };
    now += Duration::from_millis(1);
    assert_eq!(
        upload(&mut drive, now, 0x1000, 0),
        [0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0xFF, 0xFF]
    );
    // Identity, and a $NODEID default resolved for this node (0x1014 = $NODEID+0x80).
    assert_eq!(
        upload(&mut drive, now, 0x1018, 1),
        [0x43, 0x18, 0x10, 0x01, 0x55, 0x05, 0x00, 0x00]
    );
    assert_eq!(
        upload(&mut drive, now, 0x1014, 0),
        [0x43, 0x14, 0x10, 0x00, 0x85, 0x00, 0x00, 0x00]
    );
    // An object the EDS does not have: abort "object does not exist" (0x06020000).
    assert_eq!(
        upload(&mut drive, now, 0x2000, 0),
        [0x80, 0x00, 0x20, 0x00, 0x00, 0x00, 0x02, 0x06]
    );

    // Operational: TPDO1 (statusword, synchronous per the EDS) answers SYNC on 0x180 + node.
    out.clear();
    drive.handle(now, &Frame::new(0x000, &[0x01, node]).unwrap(), &mut out);
    assert_eq!(drive.nmt_state(), canmotion::canopen::NmtState::Operational);
    out.clear();
    now += Duration::from_millis(1);
    drive.handle(now, &Frame::new(0x080, &[]).unwrap(), &mut out);
    let tpdo = out
        .iter()
        .find(|f| f.id() == 0x180 + u16::from(node))
        .unwrap_or_else(|| panic!("no TPDO1 in {out:?}"));
    assert_eq!(tpdo.data().len(), 2);
    assert_eq!(
        u16::from_le_bytes([tpdo.data()[0], tpdo.data()[1]]),
        drive.statusword()
    );
}

#[test]
fn command_line_import_writes_a_loadable_file() {
    let Some(dir) = corpus() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let output = tmp.path().join("drives/cia402-slave.toml");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_canmotion"))
        .args(["dict", "import"])
        .arg(dir.join("ros2_canopen-cia402_slave.eds"))
        .arg("-o")
        .arg(&output)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(stdout.contains("70 objects"), "{stdout}");
    let d = DriveDictionary::load(&output).unwrap();
    assert_eq!(d.identity.device_type, 0xFFFF_0192);

    // A malformed file: exit status 1, `file:line: what` on stderr, nothing written.
    let bad = tmp.path().join("bad.eds");
    std::fs::write(&bad, "[1000]\nParameterName=x\nAccessType=ro\n").unwrap();
    let out2 = tmp.path().join("bad.toml");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_canmotion"))
        .args(["dict", "import"])
        .arg(&bad)
        .args(["-o"])
        .arg(&out2)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(
        stderr.contains("bad.eds:1: [1000]: missing DataType for a VAR"),
        "{stderr}"
    );
    assert!(!out2.exists());
}

#[test]
fn sections_that_look_like_objects_but_are_not_are_counted_and_named() {
    let good = "[DeviceInfo]\nVendorNumber=1\n\n[1000]\nParameterName=Device type\nObjectType=0x7\nDataType=0x0007\nAccessType=ro\nDefaultValue=0\n";
    let clean = eds::import_str(Path::new("ok.eds"), good, &ImportOptions::default()).unwrap();
    assert_eq!(clean.skipped, 0);
    let bad_names = ["0x6040", "-6040", "16040"];
    let mut text = good.to_string();
    for name in bad_names {
        text.push_str(&format!(
            "\n[{name}]\nParameterName=Controlword\nObjectType=0x7\nDataType=0x0006\nAccessType=rw\nDefaultValue=0\n"
        ));
    }
    let i = eds::import_str(Path::new("odd.eds"), &text, &ImportOptions::default()).unwrap();
    assert_eq!(i.skipped, bad_names.len(), "{}", i.summary());
    let summary = i.summary();
    assert!(summary.contains("3 skipped"), "{summary}");
    for name in bad_names {
        assert!(summary.contains(&format!("[{name}]")), "{name}: {summary}");
    }
}
