//! The dictionary TOML text: objects and sub-entries as `[[object]]` tables, with comments.

use super::*;

impl Cx<'_> {
    #[allow(clippy::too_many_arguments)]
    pub(super) fn render(
        &self,
        ini: &Ini,
        name: &str,
        [vendor, product, revision, device_type]: [u32; 4],
        node_from: Option<&str>,
        out: &BTreeMap<u16, OutObj>,
        stats: &Stats,
    ) -> String {
        let mut t = String::new();
        let file_name = self
            .file
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        comment_lines(
            &mut t,
            &format!(
                "Drive dictionary imported from the {} {} by `canmotion dict import` (canmotion {}).",
                if stats.dcf { "DCF" } else { "EDS" },
                file_name,
                env!("CARGO_PKG_VERSION")
            ),
            "# ",
            "#   ",
        );
        for (sec, keys) in [
            (
                "FileInfo",
                &[
                    "FileName",
                    "FileVersion",
                    "FileRevision",
                    "EDSVersion",
                    "Description",
                    "CreatedBy",
                    "CreationDate",
                    "ModifiedBy",
                    "ModificationDate",
                ][..],
            ),
            (
                "DeviceInfo",
                &[
                    "VendorName",
                    "VendorNumber",
                    "ProductName",
                    "ProductNumber",
                    "RevisionNumber",
                    "OrderCode",
                ][..],
            ),
        ] {
            if let Some(s) = ini.section(sec) {
                let items: Vec<String> = keys
                    .iter()
                    .filter_map(|k| s.value(k).map(|e| format!("{}={}", e.key, e.value)))
                    .collect();
                if !items.is_empty() {
                    comment_lines(
                        &mut t,
                        &format!("[{sec}] {}", items.join(", ")),
                        "# ",
                        "#   ",
                    );
                }
            }
        }
        let node = match node_from {
            Some(from) => format!(
                "Node id: $NODEID resolved for node {} ({from}).",
                self.node.unwrap_or(0)
            ),
            None => {
                "Node id: \"$NODEID+...\" defaults kept relative (the loader adds the node id)."
                    .to_string()
            }
        };
        comment_lines(&mut t, &node, "# ", "#   ");
        comment_lines(
            &mut t,
            &format!(
                "{} objects, {} entries; {} skipped; {} notes on entries (`# EDS line N:` comments).",
                stats.objects,
                stats.entries,
                self.skipped,
                stats.entry_notes.len()
            ),
            "# ",
            "#   ",
        );
        comment_lines(
            &mut t,
            "Format: see dictionaries/drives/cia402-servo.toml. Conversions: rwr/rww -> rw; \
             odd-width integers widened (range kept by min/max, not PDO-mappable); \
             UNICODE_STRING -> string; TIME_OF_DAY/TIME_DIFFERENCE -> octets.",
            "# ",
            "# ",
        );
        if !self.notes.is_empty() {
            t.push_str("#\n# Import notes:\n");
            let mut notes: Vec<&Note> = self.notes.iter().collect();
            notes.sort_by_key(|n| n.line.unwrap_or(usize::MAX));
            for n in notes {
                let text = match n.line {
                    Some(l) => format!("EDS line {l}: {}", n.text),
                    None => n.text.clone(),
                };
                comment_lines(&mut t, &text, "#   ", "#     ");
            }
        }
        if let Some(c) = ini.section("Comments") {
            let lines: Vec<&Entry> = c
                .entries
                .iter()
                .filter(|e| !e.key.eq_ignore_ascii_case("Lines"))
                .take(20)
                .collect();
            if !lines.is_empty() {
                t.push_str("#\n# [Comments] of the EDS:\n");
                for e in lines {
                    let _ = writeln!(t, "#   {}", comment_text(&e.value));
                }
            }
        }
        t.push_str("\n[device]\n");
        kv(&mut t, "name", &toml_str(name), None);
        kv(
            &mut t,
            "vendor_id",
            &format!("0x{vendor:08X}"),
            Some("0x1018:1"),
        );
        kv(
            &mut t,
            "product_code",
            &format!("0x{product:08X}"),
            Some("0x1018:2"),
        );
        kv(
            &mut t,
            "revision",
            &format!("0x{revision:08X}"),
            Some("0x1018:3"),
        );
        kv(
            &mut t,
            "device_type",
            &format!("0x{device_type:08X}"),
            Some("0x1000"),
        );

        for (&index, o) in out {
            t.push('\n');
            let mut notes = o.notes.clone();
            if o.var {
                notes.extend(o.subs[0].notes.iter().cloned());
            }
            notes.sort_by_key(|(l, _)| *l);
            for (l, n) in &notes {
                comment_lines(&mut t, &format!("EDS line {l}: {n}"), "# ", "#   ");
            }
            t.push_str("[[object]]\n");
            let origin = if o.line == 0 {
                "added by the import".to_string()
            } else {
                format!("[{}], EDS line {}", o.section, o.line)
            };
            kv(&mut t, "index", &format!("0x{index:04X}"), Some(&origin));
            kv(&mut t, "name", &toml_str(&o.name), None);
            if o.var {
                entry_keys(&mut t, index, &o.subs[0], out);
            } else {
                for s in &o.subs {
                    t.push('\n');
                    let mut notes = s.notes.clone();
                    notes.sort_by_key(|(l, _)| *l);
                    for (l, n) in &notes {
                        comment_lines(&mut t, &format!("EDS line {l}: {n}"), "# ", "#   ");
                    }
                    t.push_str("[[object.sub]]\n");
                    kv(&mut t, "sub", &s.sub.to_string(), None);
                    kv(&mut t, "name", &toml_str(&s.name), None);
                    entry_keys(&mut t, index, s, out);
                }
            }
        }
        t
    }
}

/// The keys of an entry after `name`.
pub(super) fn entry_keys(t: &mut String, index: u16, s: &OutSub, out: &BTreeMap<u16, OutObj>) {
    kv(
        t,
        "type",
        &toml_str(type_name(s.ty.out)),
        s.type_comment.as_deref(),
    );
    kv(
        t,
        "access",
        &toml_str(s.access),
        s.access_comment.as_deref(),
    );
    if s.pdo {
        kv(t, "pdo", "true", None);
    }
    // Hex for unsigned values that read as codes: the EDS wrote them so, or a 32-bit entry of
    // the communication area (COB-IDs, mapping entries, identity).
    let unsigned = matches!(s.ty.kind, Kind::Int { signed: false, .. });
    let comm_code = index::COMMUNICATION_AREA.contains(&index) && s.ty.code == 0x07;
    let hex = unsigned && (s.default_hex || comm_code);
    let mut comment: Vec<String> = Vec::new();
    if let Val::Int(v) = s.default
        && v != 0
        && s.sub >= 1
        && (index::RPDO_MAPPING_AREA.contains(&index) || index::TPDO_MAPPING_AREA.contains(&index))
        && s.ty.code == 0x07
    {
        let (mi, ms, bits) = ((v >> 16) as u16, ((v >> 8) & 0xFF) as u8, (v & 0xFF) as u8);
        let what = out
            .get(&mi)
            .map(|o| {
                o.subs
                    .iter()
                    .find(|x| x.sub == ms)
                    .map_or(o.name.clone(), |x| x.name.clone())
            })
            .unwrap_or_else(|| "not in this dictionary".to_string());
        comment.push(format!("0x{mi:04X}:{ms}, {bits} bits ({what})"));
    }
    comment.extend(s.default_comment.clone());
    comment.extend(s.default_note.as_ref().map(|(_, n)| n.clone()));
    let comment = (!comment.is_empty()).then(|| comment.join("; "));
    kv(
        t,
        "default",
        &render_val(&s.default, s.ty, hex),
        comment.as_deref(),
    );
    if let Some(b) = s.min {
        kv(t, "min", &render_bound(b, s.ty), None);
    }
    if let Some(b) = s.max {
        kv(t, "max", &render_bound(b, s.ty), None);
    }
    if let Some(u) = &s.unit {
        kv(t, "unit", &toml_str(u), None);
    }
}

pub(super) fn render_val(v: &Val, ty: Ty, hex: bool) -> String {
    match v {
        Val::Bool(b) => b.to_string(),
        Val::Int(i) if hex && *i >= 0 => format!("0x{:0w$X}", i, w = ty.hex_digits()),
        Val::Int(i) => i.to_string(),
        Val::Real(r) => float(*r),
        Val::Text(s) => toml_str(s),
        Val::NodeId(off) => toml_str(&node_text(*off)),
    }
}

pub(super) fn render_bound(b: Bound, ty: Ty) -> String {
    match b.val {
        Num::Int(i) if i > i128::from(i64::MAX) || i < i128::from(i64::MIN) => float(i as f64),
        Num::Int(i) if ty.kind == Kind::Real32 || ty.kind == Kind::Real64 => float(i as f64),
        Num::Int(i) if b.hex && matches!(ty.kind, Kind::Int { signed: false, .. }) => {
            format!("0x{:0w$X}", i, w = ty.hex_digits())
        }
        Num::Int(i) => i.to_string(),
        Num::Real(r) => float(r),
    }
}

/// A TOML float.
pub(super) fn float(r: f64) -> String {
    if r.is_nan() {
        "nan".to_string()
    } else if r.is_infinite() {
        if r > 0.0 { "inf" } else { "-inf" }.to_string()
    } else {
        format!("{r:?}")
    }
}

/// A TOML basic string.
pub(super) fn toml_str(s: &str) -> String {
    let mut o = String::with_capacity(s.len() + 2);
    o.push('"');
    for c in s.chars() {
        match c {
            '"' => o.push_str("\\\""),
            '\\' => o.push_str("\\\\"),
            '\n' => o.push_str("\\n"),
            '\t' => o.push_str("\\t"),
            '\r' => o.push_str("\\r"),
            c if (c as u32) < 0x20 || c as u32 == 0x7F => {
                let _ = write!(o, "\\u{:04X}", c as u32);
            }
            c => o.push(c),
        }
    }
    o.push('"');
    o
}

/// Text safe inside a `#` comment (no control characters).
pub(super) fn comment_text(s: &str) -> String {
    s.chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect()
}

/// `text` as `#` comment lines of at most 100 columns, broken at spaces.
pub(super) fn comment_lines(t: &mut String, text: &str, first: &str, rest: &str) {
    const WIDTH: usize = 100;
    let mut line = first.to_string();
    let mut empty = true;
    for word in comment_text(text).split(' ').filter(|w| !w.is_empty()) {
        if !empty && line.chars().count() + 1 + word.chars().count() > WIDTH {
            t.push_str(line.trim_end());
            t.push('\n');
            line = rest.to_string();
            empty = true;
        }
        if !empty {
            line.push(' ');
        }
        line.push_str(word);
        empty = false;
    }
    t.push_str(line.trim_end());
    t.push('\n');
}

/// `key = value`, with an aligned trailing comment.
pub(super) fn kv(t: &mut String, key: &str, value: &str, comment: Option<&str>) {
    let line = format!("{key} = {value}");
    let _ = match comment {
        Some(c) => writeln!(t, "{line:<28} # {}", comment_text(c)),
        None => writeln!(t, "{line}"),
    };
}
