//! From the parsed INI to the dictionary model: objects, sub-entries, bounds, identity and the
//! notes on what was skipped.

use super::render::render_bound;
use super::*;

/// One entry of the output.
#[derive(Debug, Clone)]
pub(super) struct OutSub {
    pub(super) sub: u8,
    pub(super) name: String,
    pub(super) ty: Ty,
    pub(super) type_comment: Option<String>,
    pub(super) access: &'static str,
    pub(super) access_comment: Option<String>,
    pub(super) pdo: bool,
    pub(super) default: Val,
    pub(super) default_hex: bool,
    pub(super) default_comment: Option<String>,
    /// The EDS line the default came from (the section's when there was none).
    pub(super) default_line: usize,
    /// The default was invented (none in the EDS).
    pub(super) synthesized: bool,
    /// Why the default is what it is, when the import chose it: a trailing comment.
    pub(super) default_note: Option<(usize, String)>,
    pub(super) min: Option<Bound>,
    pub(super) max: Option<Bound>,
    pub(super) unit: Option<String>,
    pub(super) notes: Vec<(usize, String)>,
}

/// A `min` or `max`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Bound {
    pub(super) val: Num,
    pub(super) hex: bool,
}

/// An integer bound is written as an integer, a real bound as a float.
#[derive(Debug, Clone, Copy)]
pub(super) enum Num {
    Int(i128),
    Real(f64),
}

impl Bound {
    pub(super) fn f64(self) -> f64 {
        match self.val {
            Num::Int(i) => i as f64,
            Num::Real(r) => r,
        }
    }
}

/// One object of the output.
#[derive(Debug, Clone)]
pub(super) struct OutObj {
    pub(super) name: String,
    pub(super) line: usize,
    pub(super) section: String,
    pub(super) notes: Vec<(usize, String)>,
    /// A variable: exactly one entry, sub 0, written inline.
    pub(super) var: bool,
    pub(super) subs: Vec<OutSub>,
}

#[derive(Debug, Default)]
pub(super) struct Stats {
    pub(super) objects: usize,
    pub(super) entries: usize,
    pub(super) dcf: bool,
    pub(super) entry_notes: Vec<Note>,
}

/// The keys of a VAR (or of a compact array's template).
pub(super) struct VarSpec<'a> {
    pub(super) name: String,
    pub(super) name_note: Option<(usize, String)>,
    pub(super) ty: Result<Ty, (u16, usize)>,
    pub(super) access: &'static str,
    pub(super) access_comment: Option<String>,
    pub(super) pdo: bool,
    pub(super) pdo_line: usize,
    pub(super) default: Option<&'a Entry>,
    pub(super) pvalue: Option<&'a Entry>,
    pub(super) low: Option<&'a Entry>,
    pub(super) high: Option<&'a Entry>,
    pub(super) unit: Option<String>,
    pub(super) line: usize,
}

pub(super) struct Cx<'a> {
    pub(super) file: &'a Path,
    pub(super) node: Option<u8>,
    pub(super) notes: Vec<Note>,
    pub(super) strict_identity: bool,
    pub(super) skipped: usize,
}

/// What a `[XXXX...]` section name is.
pub(super) enum SecName {
    Object(u16),
    Sub(u16, u8),
    Names(u16),
    Values(u16),
    Other,
}

pub(super) fn classify(name: &str) -> Result<SecName, String> {
    let b = name.as_bytes();
    if b.len() < 4 || !b[..4].iter().all(u8::is_ascii_hexdigit) {
        return Ok(SecName::Other);
    }
    let index = u16::from_str_radix(&name[..4], 16).expect("hex");
    let rest = &name[4..];
    if rest.is_empty() {
        return Ok(SecName::Object(index));
    }
    let lower = rest.to_ascii_lowercase();
    if let Some(sub) = lower.strip_prefix("sub") {
        return match u32::from_str_radix(sub, 16) {
            Ok(s) if sub.chars().all(|c| c.is_ascii_hexdigit()) && s <= 0xFF => {
                Ok(SecName::Sub(index, s as u8))
            }
            _ => Err(format!(
                "bad sub-index in section name [{name}] (expected [{}subN], N hexadecimal 0..FF)",
                &name[..4]
            )),
        };
    }
    Ok(match lower.as_str() {
        "name" => SecName::Names(index),
        "value" => SecName::Values(index),
        _ => SecName::Other,
    })
}

pub(super) fn map_access(text: &str) -> Option<(&'static str, Option<String>)> {
    Some(match text.to_ascii_lowercase().as_str() {
        "ro" => ("ro", None),
        "wo" => ("wo", None),
        "rw" => ("rw", None),
        "const" => ("const", None),
        a @ ("rwr" | "rww") => ("rw", Some(format!("{a} in the EDS"))),
        _ => return None,
    })
}

impl Cx<'_> {
    pub(super) fn err(&self, line: usize, message: impl Into<String>) -> EdsError {
        EdsError::Line {
            file: self.file.to_path_buf(),
            line,
            message: message.into(),
        }
    }

    pub(super) fn note(&mut self, line: Option<usize>, text: impl Into<String>) {
        self.notes.push(Note {
            line,
            text: text.into(),
        });
    }

    pub(super) fn skip(&mut self, line: usize, text: impl Into<String>) {
        self.skipped += 1;
        self.note(Some(line), text);
    }

    pub(super) fn convert(
        &mut self,
        ini: &Ini,
        opts: &ImportOptions,
    ) -> Result<(String, Stats), EdsError> {
        let mut stats = Stats::default();
        // Sections by role.
        let mut objects: BTreeMap<u16, &Section> = BTreeMap::new();
        let mut subs: BTreeMap<u16, BTreeMap<u8, &Section>> = BTreeMap::new();
        let mut names: BTreeMap<u16, &Section> = BTreeMap::new();
        let mut values: BTreeMap<u16, &Section> = BTreeMap::new();
        for s in &ini.sections {
            match classify(&s.name).map_err(|m| self.err(s.line, m))? {
                SecName::Object(i) => {
                    objects.insert(i, s);
                }
                SecName::Sub(i, n) => {
                    let m = subs.entry(i).or_default();
                    if let Some(prev) = m.get(&n) {
                        return Err(self.err(
                            s.line,
                            format!(
                                "section [{}] is sub-index {n} of 0x{i:04X} again (first [{}] at line {})",
                                s.name, prev.name, prev.line
                            ),
                        ));
                    }
                    m.insert(n, s);
                }
                SecName::Names(i) => {
                    names.insert(i, s);
                }
                SecName::Values(i) => {
                    values.insert(i, s);
                }
                // `[0x6040]`, `[-6040]`, `[16040]`: meant as an object, but not CiA 306's
                // four hex digits. Skipped, counted and named, never dropped silently.
                SecName::Other
                    if s.name
                        .starts_with(|c: char| c.is_ascii_digit() || c == '-' || c == '+') =>
                {
                    self.skip(
                        s.line,
                        format!(
                            "section [{}] is not an object section ([XXXX], [XXXXsubN], [XXXXName] or [XXXXValue], XXXX four hex digits): skipped",
                            s.name
                        ),
                    );
                }
                SecName::Other => {}
            }
        }
        for (i, m) in &subs {
            if !objects.contains_key(i) {
                let s = m.values().next().expect("non-empty");
                return Err(self.err(
                    s.line,
                    format!(
                        "sub-object section [{}] without its parent [{i:04X}]",
                        s.name
                    ),
                ));
            }
        }
        if objects.is_empty() {
            return Err(self.err(1, "no object sections ([1000], [1018], ...): not an EDS"));
        }

        // Node id.
        let commissioning = ini
            .section("DeviceComissioning")
            .or_else(|| ini.section("DeviceCommissioning"));
        stats.dcf = commissioning.is_some()
            || self
                .file
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("dcf"));
        let node_from = match (opts.node, commissioning.and_then(|s| s.value("NodeID"))) {
            (Some(n), _) => {
                if !(1..=127).contains(&n) {
                    return Err(self.err(1, format!("--node {n} is not a node id (1..127)")));
                }
                self.node = Some(n);
                Some(format!("--node {n}"))
            }
            (None, Some(e)) => {
                let n = parse_int(&e.value)
                    .map(|(v, _)| v)
                    .ok_or_else(|| self.err(e.line, format!("NodeID: {}", bad_number(&e.value))))?;
                if !(1..=127).contains(&n) {
                    return Err(self.err(e.line, format!("NodeID {n} is not a node id (1..127)")));
                }
                self.node = Some(n as u8);
                Some(format!("[DeviceComissioning] NodeID, line {}", e.line))
            }
            (None, None) => None,
        };

        self.check_lists(ini, &objects)?;

        if let Some(d) = ini.section("DummyUsage") {
            let mut used = Vec::new();
            for e in &d.entries {
                let on = parse_int(&e.value)
                    .filter(|(v, _)| *v == 0 || *v == 1)
                    .ok_or_else(|| self.err(e.line, format!("{}: expected 0 or 1", e.key)))?;
                if on.0 == 1 {
                    used.push(e.key.trim_start_matches(|c: char| c.is_ascii_alphabetic()));
                }
            }
            if !used.is_empty() {
                let list = used
                    .iter()
                    .map(|k| format!("0x{k}"))
                    .collect::<Vec<_>>()
                    .join(" ");
                self.note(
                    Some(d.line),
                    format!(
                        "[DummyUsage]: the device accepts dummy mapping of {list}; this format has no dummy entries"
                    ),
                );
            }
        }

        // Objects.
        let mut out: BTreeMap<u16, OutObj> = BTreeMap::new();
        for (&index, sec) in &objects {
            if let Some(o) = self.object(index, sec, &subs, &names, &values)? {
                out.insert(index, o);
            }
        }

        // Identity.
        let info = ini.section("DeviceInfo");
        let identity = self.identity(&mut out, info)?;

        // Name.
        let name = {
            let get = |k: &str| info.and_then(|s| s.value(k)).map(|e| e.value.clone());
            match (get("VendorName"), get("ProductName")) {
                (Some(v), Some(p)) => format!("{v} {p}"),
                (None, Some(p)) => p,
                (v, None) => ini
                    .section("FileInfo")
                    .and_then(|s| s.value("Description"))
                    .map(|e| e.value.clone())
                    .or(v)
                    .unwrap_or_else(|| {
                        self.file
                            .file_stem()
                            .map(|s| s.to_string_lossy().into_owned())
                            .unwrap_or_else(|| "imported drive".to_string())
                    }),
            }
        };

        stats.objects = out.len();
        stats.entries = out.values().map(|o| o.subs.len()).sum();
        for o in out.values() {
            for (l, t) in &o.notes {
                stats.entry_notes.push(Note {
                    line: Some(*l),
                    text: t.clone(),
                });
            }
            for s in &o.subs {
                for (l, t) in s.notes.iter().chain(&s.default_note) {
                    stats.entry_notes.push(Note {
                        line: Some(*l),
                        text: t.clone(),
                    });
                }
            }
        }
        let text = self.render(ini, &name, identity, node_from.as_deref(), &out, &stats);
        Ok((text, stats))
    }

    /// The object lists: listed objects without a section and sections in no list are noted.
    pub(super) fn check_lists(
        &mut self,
        ini: &Ini,
        objects: &BTreeMap<u16, &Section>,
    ) -> Result<(), EdsError> {
        let mut listed: BTreeSet<u16> = BTreeSet::new();
        for list in ["MandatoryObjects", "OptionalObjects", "ManufacturerObjects"] {
            let Some(s) = ini.section(list) else { continue };
            let mut count = None;
            let mut n = 0usize;
            for e in &s.entries {
                if e.key.eq_ignore_ascii_case("SupportedObjects") {
                    count = Some(parse_int(&e.value).map(|(v, _)| v).ok_or_else(|| {
                        self.err(
                            e.line,
                            format!("SupportedObjects: {}", bad_number(&e.value)),
                        )
                    })?);
                    continue;
                }
                if parse_int(&e.key).is_none() {
                    return Err(self.err(
                        e.line,
                        format!(
                            "unexpected key {:?} in [{}] (expected n=0xIIII)",
                            e.key, s.name
                        ),
                    ));
                }
                let index = parse_int(&e.value)
                    .and_then(|(v, _)| u16::try_from(v).ok())
                    .ok_or_else(|| {
                        self.err(
                            e.line,
                            format!("{}: bad object index {:?} in [{}]", e.key, e.value, s.name),
                        )
                    })?;
                if !objects.contains_key(&index) {
                    self.note(
                        Some(e.line),
                        format!(
                            "object 0x{index:04X} is listed in [{}] but has no [{index:04X}] section: not imported",
                            s.name
                        ),
                    );
                }
                listed.insert(index);
                n += 1;
            }
            if let Some(c) = count
                && c != n as i128
            {
                self.note(
                    Some(s.line),
                    format!("[{}] says SupportedObjects={c} but lists {n}", s.name),
                );
            }
        }
        let unlisted: Vec<String> = objects
            .keys()
            .filter(|i| **i >= *index::COMMUNICATION_AREA.start() && !listed.contains(i))
            .map(|i| format!("0x{i:04X}"))
            .collect();
        if !unlisted.is_empty() {
            let shown = if unlisted.len() > 12 {
                format!(
                    "{} ... ({} in all)",
                    unlisted[..12].join(" "),
                    unlisted.len()
                )
            } else {
                unlisted.join(" ")
            };
            self.note(
                None,
                format!("object sections in no object list, imported anyway: {shown}"),
            );
        }
        Ok(())
    }

    /// Read the keys of a VAR-like section.
    pub(super) fn var_spec<'s>(
        &self,
        sec: &'s Section,
        fallback_name: String,
        domain: bool,
    ) -> Result<VarSpec<'s>, EdsError> {
        let (name, name_note) = match sec.value("ParameterName") {
            Some(e) => (e.value.clone(), None),
            None => (
                fallback_name.clone(),
                Some((
                    sec.line,
                    format!("no ParameterName: named {fallback_name:?}"),
                )),
            ),
        };
        let ty = match sec.value("DataType") {
            Some(e) => {
                let code = parse_int(&e.value)
                    .and_then(|(v, _)| u16::try_from(v).ok())
                    .ok_or_else(|| {
                        self.err(e.line, format!("DataType: {}", bad_number(&e.value)))
                    })?;
                Ty::from_code(code).ok_or((code, e.line))
            }
            None if domain => Ok(Ty::from_code(0x0F).expect("DOMAIN")),
            None => {
                return Err(self.err(
                    sec.line,
                    format!("[{}]: missing DataType for a VAR", sec.name),
                ));
            }
        };
        let (access, access_comment) = match sec.value("AccessType") {
            Some(e) => map_access(&e.value).ok_or_else(|| {
                self.err(
                    e.line,
                    format!(
                        "AccessType {:?} is not one of ro wo rw rwr rww const",
                        e.value
                    ),
                )
            })?,
            None if domain => ("rw", Some("no AccessType in the EDS".to_string())),
            None => {
                return Err(self.err(
                    sec.line,
                    format!("[{}]: missing AccessType for a VAR", sec.name),
                ));
            }
        };
        let (pdo, pdo_line) = match sec.value("PDOMapping") {
            Some(e) => {
                let v = if e.value.eq_ignore_ascii_case("true") {
                    1
                } else if e.value.eq_ignore_ascii_case("false") {
                    0
                } else {
                    parse_int(&e.value).map(|(v, _)| v).unwrap_or(-1)
                };
                if v != 0 && v != 1 {
                    return Err(
                        self.err(e.line, format!("PDOMapping {:?}: expected 0 or 1", e.value))
                    );
                }
                (v == 1, e.line)
            }
            None => (false, sec.line),
        };
        Ok(VarSpec {
            name,
            name_note,
            ty,
            access,
            access_comment,
            pdo,
            pdo_line,
            default: sec.value("DefaultValue"),
            pvalue: sec.value("ParameterValue"),
            low: sec.value("LowLimit"),
            high: sec.value("HighLimit"),
            unit: sec.value("Unit").map(|e| e.value.clone()),
            line: sec.line,
        })
    }

    /// A limit, or `None` with a note when it cannot be kept.
    pub(super) fn bound(
        &self,
        ty: Ty,
        e: Option<&Entry>,
        notes: &mut Vec<(usize, String)>,
    ) -> Result<Option<Bound>, EdsError> {
        let Some(e) = e else { return Ok(None) };
        if !ty.numeric() {
            notes.push((
                e.line,
                format!(
                    "{}={} on a {} dropped (ranges are for numbers)",
                    e.key, e.value, ty.cia
                ),
            ));
            return Ok(None);
        }
        let p = match parse_value(ty, &e.value, self.node) {
            Ok(p) => p,
            Err(VErr::Syntax(m)) => return Err(self.err(e.line, format!("{}: {m}", e.key))),
            Err(VErr::Range(m)) => {
                notes.push((e.line, format!("{} dropped: {m}", e.key)));
                return Ok(None);
            }
        };
        if let Val::Real(r) = p.val
            && !r.is_finite()
        {
            notes.push((
                e.line,
                format!("{}={} dropped: not a finite number", e.key, e.value),
            ));
            return Ok(None);
        }
        Ok(Some(match p.val {
            Val::Int(i) => Bound {
                val: Num::Int(i),
                hex: p.hex,
            },
            Val::Bool(b) => Bound {
                val: Num::Int(i128::from(b)),
                hex: false,
            },
            Val::Real(r) if ty.kind == Kind::Real32 => Bound {
                val: Num::Real(f64::from(r as f32)),
                hex: false,
            },
            Val::Real(r) => Bound {
                val: Num::Real(r),
                hex: false,
            },
            Val::NodeId(off) => {
                notes.push((
                    e.line,
                    format!(
                        "{}={} dropped: a bound must be a number, and there is no node id",
                        e.key,
                        node_text(off)
                    ),
                ));
                return Ok(None);
            }
            Val::Text(_) => unreachable!("numeric type"),
        }))
    }

    /// Convert one VAR-like spec to an entry; `Ok(Err(reason))` skips it.
    pub(super) fn entry(
        &self,
        spec: &VarSpec,
        sub: u8,
        name: String,
        value: Option<&Entry>,
    ) -> Result<Result<OutSub, String>, EdsError> {
        let ty = match spec.ty {
            Ok(t) => t,
            Err((code, _)) => {
                return Ok(Err(format!(
                    "DataType 0x{code:04X} is not a CiA 301 basic type"
                )));
            }
        };
        let mut notes: Vec<(usize, String)> = Vec::new();
        if let Some(n) = &spec.name_note {
            notes.push(n.clone());
        }
        let type_comment = if ty.widened() {
            Some(format!(
                "{} in the EDS: widened to {} bits, range kept by min/max",
                ty.cia,
                ty.out.size() * 8
            ))
        } else if ty.code == 0x0B {
            Some("UNICODE_STRING in the EDS: kept as UTF-8 text".to_string())
        } else if matches!(ty.code, 0x0C | 0x0D) {
            Some(format!("{} in the EDS: raw octets", ty.cia))
        } else {
            None
        };
        let mut pdo = spec.pdo;
        if pdo && ty.out.fixed_size().is_none() {
            pdo = false;
            notes.push((
                spec.pdo_line,
                format!(
                    "PDOMapping=1 on a variable-length {} dropped (our loader cannot map it)",
                    ty.cia
                ),
            ));
        }
        if pdo && ty.widened() {
            pdo = false;
            notes.push((
                spec.pdo_line,
                format!(
                    "PDOMapping=1 dropped: the {} is {} bits in a PDO of the real device, {} here",
                    ty.cia,
                    match ty.kind {
                        Kind::Int { bits, .. } => bits,
                        _ => 0,
                    },
                    ty.out.size() * 8
                ),
            ));
        }

        // Default, ParameterValue, [XXXXValue].
        let parse_at = |e: &Entry| -> Result<Parsed, EdsError> {
            parse_value(ty, &e.value, self.node)
                .map_err(|m| self.err(e.line, format!("{} {:?}: {}", e.key, e.value, m.message())))
        };
        let eds_default = spec.default.map(parse_at).transpose()?;
        let eds_default_val = eds_default.as_ref().map(|p| p.val.clone());
        let pvalue = spec.pvalue.map(parse_at).transpose()?;
        let over = value.map(parse_at).transpose()?;
        let (chosen, chosen_entry, source) = if let (Some(p), Some(e)) = (over, value) {
            (Some(p), Some(e), Some(format!("[{}] value", e.key)))
        } else if let (Some(p), Some(e)) = (pvalue, spec.pvalue) {
            (Some(p), Some(e), Some("ParameterValue".to_string()))
        } else {
            (eds_default, spec.default, None)
        };

        let mut min = self.bound(ty, spec.low, &mut notes)?;
        let mut max = self.bound(ty, spec.high, &mut notes)?;
        if let (Some(lo), Some(hi)) = (min, max)
            && lo.f64() > hi.f64()
        {
            notes.push((
                spec.low.map_or(spec.line, |e| e.line),
                format!(
                    "LowLimit {} is above HighLimit {}: both dropped",
                    spec.low.map_or("", |e| e.value.as_str()),
                    spec.high.map_or("", |e| e.value.as_str())
                ),
            ));
            min = None;
            max = None;
        }
        if ty.widened() {
            let (lo, hi) = ty.int_range().expect("integer");
            if min.is_none() && lo < 0 {
                min = Some(Bound {
                    val: Num::Int(lo),
                    hex: false,
                });
            }
            if max.is_none() {
                max = Some(Bound {
                    val: Num::Int(hi),
                    hex: true,
                });
            }
        }

        let (mut default, mut default_hex, mut default_comment, default_line, synthesized) =
            match chosen {
                Some(p) => {
                    let e = chosen_entry.expect("entry");
                    for n in p.notes {
                        notes.push((e.line, n));
                    }
                    let comment = match (source, p.comment) {
                        (Some(_), c) if eds_default_val.as_ref() == Some(&p.val) => c,
                        (Some(src), c) => {
                            let was = spec
                                .default
                                .map(|d| format!("; DefaultValue {}", d.value))
                                .unwrap_or_default();
                            Some(match c {
                                Some(c) => format!("{src} ({c}){was}"),
                                None => format!("{src}{was}"),
                            })
                        }
                        (None, c) => c,
                    };
                    (p.val, p.hex, comment, e.line, false)
                }
                None => {
                    let zero = match ty.kind {
                        Kind::Bool => Val::Bool(false),
                        Kind::Int { .. } => Val::Int(0),
                        Kind::Real32 | Kind::Real64 => Val::Real(0.0),
                        Kind::Text | Kind::Bytes => Val::Text(String::new()),
                    };
                    (zero, false, None, spec.line, true)
                }
            };
        let mut from_bound = |b: Bound| -> Val {
            match (b.val, ty.kind) {
                (Num::Int(i), Kind::Bool) => Val::Bool(i != 0),
                (Num::Int(i), Kind::Int { .. }) => {
                    default_hex = b.hex;
                    Val::Int(i)
                }
                (Num::Int(i), _) => Val::Real(i as f64),
                (Num::Real(r), _) => Val::Real(r),
            }
        };
        let mut default_note = None;
        if synthesized {
            let mut how = "0";
            if let Some(lo) = min.filter(|lo| lo.f64() > 0.0) {
                default = from_bound(lo);
                how = "the LowLimit, as 0 is below it";
            } else if let Some(hi) = max.filter(|hi| hi.f64() < 0.0) {
                default = from_bound(hi);
                how = "the HighLimit, as 0 is above it";
            }
            let how = if ty.numeric() { how } else { "empty" };
            default_note = Some((spec.line, format!("no DefaultValue in the EDS: {how}")));
        } else if let Some(x) = default.as_f64(ty) {
            if let Some(lo) = min.filter(|lo| x < lo.f64()) {
                notes.push((
                    spec.low.map_or(spec.line, |e| e.line),
                    format!(
                        "LowLimit {} dropped: the default is below it",
                        render_bound(lo, ty)
                    ),
                ));
                min = None;
            }
            if let Some(hi) = max.filter(|hi| x > hi.f64()) {
                notes.push((
                    spec.high.map_or(spec.line, |e| e.line),
                    format!(
                        "HighLimit {} dropped: the default is above it",
                        render_bound(hi, ty)
                    ),
                ));
                max = None;
            }
        }
        if let Val::Int(v) = default
            && v > i128::from(i64::MAX)
        {
            notes.push((
                default_line,
                format!(
                    "default 0x{v:X} is above what TOML integers hold (i64): default 0 instead"
                ),
            ));
            default = Val::Int(0);
            default_comment = None;
            if min.is_some_and(|lo| lo.f64() > 0.0) {
                min = None;
            }
        }
        Ok(Ok(OutSub {
            sub,
            name,
            ty,
            type_comment,
            access: spec.access,
            access_comment: spec.access_comment.clone(),
            pdo,
            default,
            default_hex,
            default_comment,
            default_line,
            synthesized,
            default_note,
            min,
            max,
            unit: spec.unit.clone(),
            notes,
        }))
    }

    /// Convert one `[XXXX]` object; `None` when it is skipped.
    pub(super) fn object(
        &mut self,
        index: u16,
        sec: &Section,
        subs: &BTreeMap<u16, BTreeMap<u8, &Section>>,
        names: &BTreeMap<u16, &Section>,
        values: &BTreeMap<u16, &Section>,
    ) -> Result<Option<OutObj>, EdsError> {
        let ot = match sec.value("ObjectType") {
            Some(e) => parse_int(&e.value)
                .and_then(|(v, _)| u8::try_from(v).ok())
                .ok_or_else(|| self.err(e.line, format!("ObjectType: {}", bad_number(&e.value))))?,
            None => 0x7,
        };
        let my_subs = subs.get(&index);
        let title = sec
            .value("ParameterName")
            .map(|e| e.value.clone())
            .unwrap_or_else(|| format!("Object 0x{index:04X}"));
        if index < *index::COMMUNICATION_AREA.start() || matches!(ot, 0x0 | 0x5 | 0x6) {
            self.skip(
                sec.line,
                format!(
                    "[{}] {title:?}: a data type definition (ObjectType 0x{ot:X}), not an object: skipped",
                    sec.name
                ),
            );
            return Ok(None);
        }
        let mut obj = OutObj {
            name: title.clone(),
            line: sec.line,
            section: sec.name.clone(),
            notes: Vec::new(),
            var: false,
            subs: Vec::new(),
        };
        match ot {
            0x7 | 0x2 => {
                if let Some(m) = my_subs {
                    let s = m.values().next().expect("non-empty");
                    return Err(self.err(
                        s.line,
                        format!(
                            "sub-object section [{}] of 0x{index:04X}, which is a VAR (line {})",
                            s.name, sec.line
                        ),
                    ));
                }
                if sec.value("CompactSubObj").is_some() {
                    obj.notes
                        .push((sec.line, "CompactSubObj on a VAR ignored".to_string()));
                }
                let spec = self.var_spec(sec, title.clone(), ot == 0x2)?;
                match self.entry(&spec, 0, spec.name.clone(), None)? {
                    Ok(s) => {
                        obj.var = true;
                        obj.subs.push(s);
                    }
                    Err(why) => {
                        let line = spec.ty.err().map_or(sec.line, |(_, l)| l);
                        self.skip(line, format!("0x{index:04X} {title:?}: {why}: skipped"));
                        return Ok(None);
                    }
                }
            }
            0x8 | 0x9 => {
                let compact = match sec.value("CompactSubObj") {
                    Some(e) => {
                        let n = parse_int(&e.value).map(|(v, _)| v).ok_or_else(|| {
                            self.err(e.line, format!("CompactSubObj: {}", bad_number(&e.value)))
                        })?;
                        if !(0..=254).contains(&n) {
                            return Err(
                                self.err(e.line, format!("CompactSubObj {n}: expected 0..254"))
                            );
                        }
                        (n > 0).then_some((n as u8, e.line))
                    }
                    None => None,
                };
                if let Some((n, cline)) = compact {
                    if let Some(m) = my_subs {
                        let s = m.values().next().expect("non-empty");
                        return Err(self.err(
                            s.line,
                            format!(
                                "sub-object section [{}] for 0x{index:04X}, which has CompactSubObj={n} (line {cline})",
                                s.name
                            ),
                        ));
                    }
                    self.compact(
                        index,
                        sec,
                        n,
                        cline,
                        names.get(&index),
                        values.get(&index),
                        &mut obj,
                    )?;
                } else {
                    for s in [names.get(&index), values.get(&index)]
                        .into_iter()
                        .flatten()
                    {
                        obj.notes.push((
                            s.line,
                            format!("[{}] ignored: 0x{index:04X} is not a compact array", s.name),
                        ));
                    }
                    if let Some(m) = my_subs {
                        for (&n, s) in m {
                            let spec = self.var_spec(s, format!("{title} {n}"), false)?;
                            match self.entry(&spec, n, spec.name.clone(), None)? {
                                Ok(e) => obj.subs.push(e),
                                Err(why) => {
                                    let line = spec.ty.err().map_or(s.line, |(_, l)| l);
                                    self.skip(
                                        line,
                                        format!(
                                            "0x{index:04X}:{n} {:?}: {why}: skipped",
                                            spec.name
                                        ),
                                    );
                                }
                            }
                        }
                    }
                }
                if obj.subs.is_empty() {
                    self.skip(
                        sec.line,
                        format!(
                            "0x{index:04X} {title:?}: {} without any sub-entry: skipped",
                            if ot == 0x8 { "ARRAY" } else { "RECORD" }
                        ),
                    );
                    return Ok(None);
                }
            }
            other => {
                return Err(self.err(
                    sec.value("ObjectType").map_or(sec.line, |e| e.line),
                    format!("unknown ObjectType 0x{other:X} (expected 0x7 VAR, 0x8 ARRAY, 0x9 RECORD, 0x2 DOMAIN, 0x5 DEFTYPE, 0x6 DEFSTRUCT)"),
                ));
            }
        }
        Ok(Some(obj))
    }

    /// The entries of a `[XXXXName]` or `[XXXXValue]` section by sub-index 1..=n.
    pub(super) fn per_sub<'s>(
        &self,
        s: Option<&'s Section>,
        n: u8,
    ) -> Result<BTreeMap<u8, &'s Entry>, EdsError> {
        let mut m = BTreeMap::new();
        if let Some(s) = s {
            for e in &s.entries {
                if e.key.eq_ignore_ascii_case("NrOfEntries") {
                    continue;
                }
                let k = parse_int(&e.key)
                    .and_then(|(v, _)| u8::try_from(v).ok())
                    .filter(|&k| k >= 1 && k <= n)
                    .ok_or_else(|| {
                        self.err(
                            e.line,
                            format!(
                                "[{}]: key {:?} is not a sub-index 1..{n} of the compact array",
                                s.name, e.key
                            ),
                        )
                    })?;
                m.insert(k, e);
            }
        }
        Ok(m)
    }

    /// The sub-entries of a compact array (CiA 306): sub 0 holds the count, subs 1..=n are built
    /// from the object's own keys, named by `[XXXXName]` and valued by `[XXXXValue]` if present.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn compact(
        &mut self,
        index: u16,
        sec: &Section,
        n: u8,
        cline: usize,
        names: Option<&&Section>,
        values: Option<&&Section>,
        obj: &mut OutObj,
    ) -> Result<(), EdsError> {
        let spec = self.var_spec(sec, obj.name.clone(), false)?;
        let names = self.per_sub(names.copied(), n)?;
        let values = self.per_sub(values.copied(), n)?;
        obj.notes.push((
            cline,
            format!("CompactSubObj={n}: sub-entries 0..{n} generated per CiA 306"),
        ));
        let count = OutSub {
            sub: 0,
            name: "Highest sub-index supported".to_string(),
            ty: Ty::u8(),
            type_comment: None,
            access: "ro",
            access_comment: None,
            pdo: false,
            default: Val::Int(i128::from(n)),
            default_hex: false,
            default_comment: None,
            default_line: cline,
            synthesized: false,
            default_note: None,
            min: None,
            max: None,
            unit: None,
            notes: Vec::new(),
        };
        obj.subs.push(count);
        for k in 1..=n {
            let name = names
                .get(&k)
                .map(|e| e.value.clone())
                .filter(|s| !s.is_empty())
                .unwrap_or_else(|| format!("{} {k}", spec.name));
            match self.entry(&spec, k, name, values.get(&k).copied())? {
                Ok(mut e) => {
                    if k > 1 {
                        // The template's notes are said once, on sub 1.
                        e.notes.clear();
                    }
                    obj.subs.push(e);
                }
                Err(why) => {
                    let line = spec.ty.err().map_or(sec.line, |(_, l)| l);
                    self.skip(
                        line,
                        format!("0x{index:04X} {:?}: {why}: skipped", obj.name),
                    );
                    obj.subs.clear();
                    return Ok(());
                }
            }
        }
        Ok(())
    }

    /// Fill and check the identity: 0x1000 and 0x1018:1..3 against `[DeviceInfo]`.
    pub(super) fn identity(
        &mut self,
        out: &mut BTreeMap<u16, OutObj>,
        info: Option<&Section>,
    ) -> Result<[u32; 4], EdsError> {
        let new_sub =
            |sub: u8, name: &str, ty: Ty, access: &'static str, v: i128, line: usize| OutSub {
                sub,
                name: name.to_string(),
                ty,
                type_comment: None,
                access,
                access_comment: None,
                pdo: false,
                default: Val::Int(v),
                default_hex: ty.code == 0x07,
                default_comment: None,
                default_line: line,
                synthesized: false,
                default_note: None,
                min: None,
                max: None,
                unit: None,
                notes: Vec::new(),
            };
        // 0x1000.
        let device_type = match out.get_mut(&index::DEVICE_TYPE) {
            None => {
                self.note(
                    None,
                    "the EDS has no object 0x1000: added (UNSIGNED32, ro, device type 0)",
                );
                out.insert(
                    index::DEVICE_TYPE,
                    OutObj {
                        name: "Device type".to_string(),
                        line: 0,
                        section: String::new(),
                        notes: vec![],
                        var: true,
                        subs: vec![new_sub(0, "Device type", Ty::u32(), "ro", 0, 0)],
                    },
                );
                0
            }
            Some(o) => {
                let line = o.line;
                if !o.var {
                    return Err(self.err(line, "object 0x1000 (device type) must be a VAR"));
                }
                let s = &mut o.subs[0];
                s.default_hex = true;
                match s.default {
                    Val::Int(v) if (0..=i128::from(u32::MAX)).contains(&v) => {
                        if s.synthesized {
                            self.note(None, "0x1000 has no DefaultValue: device type 0");
                        }
                        v as u32
                    }
                    Val::NodeId(_) => {
                        return Err(self.err(
                            s.default_line,
                            "the device type (0x1000) cannot depend on $NODEID",
                        ));
                    }
                    _ => {
                        return Err(self.err(
                            line,
                            format!(
                                "object 0x1000 (device type) must be UNSIGNED32, not {}",
                                s.ty.cia
                            ),
                        ));
                    }
                }
            }
        };
        // 0x1018.
        let o = match out.get_mut(&index::IDENTITY) {
            Some(o) if o.var => {
                return Err(self.err(o.line, "object 0x1018 (identity) must be a RECORD"));
            }
            Some(o) => o,
            None => {
                self.note(
                    None,
                    "the EDS has no object 0x1018: added (sub 0 and 1..3, from [DeviceInfo])",
                );
                out.insert(
                    index::IDENTITY,
                    OutObj {
                        name: "Identity object".to_string(),
                        line: 0,
                        section: String::new(),
                        notes: vec![],
                        var: false,
                        subs: vec![new_sub(
                            0,
                            "Highest sub-index supported",
                            Ty::u8(),
                            "const",
                            3,
                            0,
                        )],
                    },
                );
                out.get_mut(&index::IDENTITY).expect("inserted")
            }
        };
        let mut ids = [0u32; 3];
        for (k, (key, sub_name)) in [
            ("VendorNumber", "Vendor-ID"),
            ("ProductNumber", "Product code"),
            ("RevisionNumber", "Revision number"),
        ]
        .into_iter()
        .enumerate()
        {
            let sub = k as u8 + 1;
            let di = match info.and_then(|s| s.value(key)) {
                Some(e) => Some((
                    parse_int(&e.value)
                        .map(|(v, _)| v)
                        .filter(|v| (0..=i128::from(u32::MAX)).contains(v))
                        .ok_or_else(|| {
                            self.err(e.line, format!("{key} {:?} is not an UNSIGNED32", e.value))
                        })?,
                    e.line,
                )),
                None => None,
            };
            let pos = o.subs.iter().position(|s| s.sub == sub);
            let Some(pos) = pos else {
                let (v, how) = match di {
                    Some((v, l)) => (v, format!("from [DeviceInfo] {key} (line {l})")),
                    None => (0, "0 (no [DeviceInfo] either)".to_string()),
                };
                self.note(
                    None,
                    format!("0x1018:{sub} ({sub_name}) is missing in the EDS: added, {how}"),
                );
                let at = o
                    .subs
                    .iter()
                    .position(|s| s.sub > sub)
                    .unwrap_or(o.subs.len());
                let mut s = new_sub(sub, sub_name, Ty::u32(), "ro", v, 0);
                s.default_comment = Some(format!("added: {how}"));
                o.subs.insert(at, s);
                ids[k] = v as u32;
                continue;
            };
            let s = &mut o.subs[pos];
            if s.ty.code != 0x07 {
                return Err(self.err(
                    s.default_line,
                    format!(
                        "0x1018:{sub} ({sub_name}) must be UNSIGNED32, not {}",
                        s.ty.cia
                    ),
                ));
            }
            s.default_hex = true;
            let obj_val = match s.default {
                Val::Int(v) => v,
                Val::NodeId(_) => {
                    return Err(self.err(
                        s.default_line,
                        format!("0x1018:{sub} ({sub_name}) cannot depend on $NODEID"),
                    ));
                }
                _ => unreachable!("UNSIGNED32"),
            };
            let v = match (s.synthesized, di) {
                (false, Some((d, dl))) if d != obj_val => {
                    let msg = format!(
                        "0x1018:{sub} ({sub_name}) default 0x{obj_val:08X} contradicts [DeviceInfo] {key} 0x{d:08X} at line {dl}"
                    );
                    if self.strict_identity {
                        return Err(self.err(s.default_line, msg));
                    }
                    self.note(Some(s.default_line), format!("{msg}: [DeviceInfo] wins"));
                    s.default = Val::Int(d);
                    s.default_comment = Some(format!(
                        "[DeviceInfo] {key}; the EDS default was 0x{obj_val:X}"
                    ));
                    d
                }
                (true, Some((d, dl))) => {
                    s.default_note = Some((
                        s.default_line,
                        format!("no DefaultValue in the EDS: [DeviceInfo] {key} (line {dl})"),
                    ));
                    s.default = Val::Int(d);
                    d
                }
                (true, None) => {
                    self.note(
                        None,
                        format!(
                            "0x1018:{sub} ({sub_name}) has no default and [DeviceInfo] no {key}: 0"
                        ),
                    );
                    s.default = Val::Int(0);
                    0
                }
                (false, _) => obj_val,
            };
            // An identity entry is read-only and its value is the device's: a range on it (an
            // EDS may give one, even a $NODEID-dependent one) cannot be honoured once the value
            // comes from [DeviceInfo], so it goes.
            if v != obj_val || s.synthesized {
                s.min = None;
                s.max = None;
            }
            ids[k] = v as u32;
        }
        Ok([ids[0], ids[1], ids[2], device_type])
    }
}
