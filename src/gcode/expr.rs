//! Parameters (`#1`, `#<name>`) and expressions (`[1 + #2 * SIN[30]]`) of RS274/NGC.
//!
//! Grammar (LinuxCNC's): a value is a number, `#` followed by a value (the parameter of that
//! number) or `<name>`, `[expression]`, a function `ABS ACOS ASIN COS EXP FIX FUP ROUND LN SIN
//! SQRT TAN [value]`, `ATAN[y]/[x]`, `EXISTS[#<name>]`, or a sign followed by a value. Binary
//! operators from the lowest precedence: `AND OR XOR`, `EQ NE GT GE LT LE`, `+ -`,
//! `* / MOD`, `**`; left to right within a level. Angles are in degrees. Blanks are allowed
//! anywhere between tokens. Every error has the column where it was found.

use std::collections::HashMap;

use super::ErrorKind;

/// How deep brackets, functions and `#` may nest in one value (a bound on recursion).
pub const MAX_NESTING: usize = 64;

/// Numbered parameters a program may set: `#1` … `#4999` (`#1`–`#30` are a subroutine's
/// arguments and locals). `#5000` and above are LinuxCNC's system parameters.
pub const MAX_USER_PARAMETER: u32 = 4999;

/// Most named parameters one scope (the main program or one call) may hold.
pub const MAX_NAMED_PARAMETERS: usize = 10_000;

/// LinuxCNC's predefined named parameters (`interp_namedparams.cc`) that the interpreter
/// keeps, read-only, in the order of the values [`Params::set_predefined`] takes.
pub(super) const PREDEFINED: [&str; 33] = [
    "_line",
    "_motion_mode",
    "_plane",
    "_ccomp",
    "_metric",
    "_imperial",
    "_absolute",
    "_incremental",
    "_inverse_time",
    "_units_per_minute",
    "_units_per_rev",
    "_coord_system",
    "_tool_offset",
    "_retract_r_plane",
    "_retract_old_z",
    "_spindle_rpm_mode",
    "_spindle_css_mode",
    "_ijk_absolute_mode",
    "_lathe_diameter_mode",
    "_lathe_radius_mode",
    "_spindle_on",
    "_spindle_cw",
    "_feed",
    "_rpm",
    "_current_tool",
    "_selected_tool",
    "_x",
    "_y",
    "_z",
    "_abs_x",
    "_abs_y",
    "_abs_z",
    "_remap_level",
];

/// LinuxCNC's predefined named parameters that hold state this front end does not keep
/// (version, coolant, overrides, pockets, the axes it does not have): read-only, and reading
/// one is [`ErrorKind::Unsupported`].
const PREDEFINED_NOT_KEPT: [&str; 19] = [
    "_vmajor",
    "_vminor",
    "_mist",
    "_flood",
    "_speed_override",
    "_feed_override",
    "_adaptive_feed",
    "_feed_hold",
    "_current_pocket",
    "_selected_pocket",
    "_a",
    "_b",
    "_c",
    "_u",
    "_v",
    "_w",
    "_abs_a",
    "_abs_b",
    "_abs_c",
];

/// The predefined parameters the store itself answers: the last return value, whether the
/// last return gave one, the call level.
const PREDEFINED_OWN: [&str; 3] = ["_value", "_value_returned", "_call_level"];

/// Whether `name` (lower case) is one of LinuxCNC's predefined named parameters.
fn is_predefined(name: &str) -> bool {
    PREDEFINED.contains(&name)
        || PREDEFINED_OWN.contains(&name)
        || PREDEFINED_NOT_KEPT.contains(&name)
}

/// An error with its 1-based column.
pub(super) type ExprError = (usize, ErrorKind);

/// A parameter reference.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum ParamRef {
    /// `#n`.
    Number(u32),
    /// `#<name>`, lower-cased, blanks removed. Names starting with `_` are global, others are
    /// local to the subroutine call (or to the main program).
    Name(String),
}

#[derive(Debug, Clone, PartialEq)]
struct Scope {
    /// `#1` … `#30`.
    locals: [f64; 30],
    named: HashMap<String, f64>,
}

impl Scope {
    fn new() -> Scope {
        Scope {
            locals: [0.0; 30],
            named: HashMap::new(),
        }
    }
}

/// The parameter store: global numbered and named parameters, and a scope per call level.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Params {
    numbered: HashMap<u32, f64>,
    global: HashMap<String, f64>,
    scopes: Vec<Scope>,
    /// The read-only system parameters kept (`#5070`, `#5220`, `#5420`…), as the interpreter
    /// last set them.
    system: HashMap<u32, f64>,
    /// The values of [`PREDEFINED`], as the interpreter last set them.
    predefined: [f64; PREDEFINED.len()],
    /// `#<_value>`: the value the last `return`/`endsub` gave.
    return_value: f64,
    /// `#<_value_returned>`: whether the last `return`/`endsub` gave one.
    value_returned: bool,
}

impl Default for Params {
    fn default() -> Params {
        Params {
            numbered: HashMap::new(),
            global: HashMap::new(),
            scopes: vec![Scope::new()],
            system: HashMap::new(),
            predefined: [0.0; PREDEFINED.len()],
            return_value: 0.0,
            value_returned: false,
        }
    }
}

impl Params {
    fn scope(&self) -> &Scope {
        // There is always the main program's scope.
        self.scopes.last().unwrap_or_else(|| unreachable!())
    }

    fn scope_mut(&mut self) -> &mut Scope {
        if self.scopes.is_empty() {
            self.scopes.push(Scope::new());
        }
        let last = self.scopes.len() - 1;
        &mut self.scopes[last]
    }

    /// The value of a parameter.
    pub fn get(&self, r: &ParamRef) -> Result<f64, ErrorKind> {
        match r {
            ParamRef::Number(n @ 1..=30) => Ok(self.scope().locals[*n as usize - 1]),
            ParamRef::Number(n) if *n <= MAX_USER_PARAMETER => {
                Ok(self.numbered.get(n).copied().unwrap_or(0.0))
            }
            ParamRef::Number(n) => self
                .system
                .get(n)
                .copied()
                .ok_or_else(|| system_parameter(*n)),
            ParamRef::Name(name) if name.starts_with('_') && is_predefined(name) => {
                self.predefined(name)
            }
            ParamRef::Name(name) if name.starts_with("_ini[") || name.starts_with("_hal[") => {
                Err(ErrorKind::Unsupported {
                    what: format!("parameter #<{name}>"),
                    reason: "LinuxCNC reads it from its INI file or a HAL pin; this controller has a TOML machine file and no HAL: put the value in the program or in a parameter of your own",
                })
            }
            ParamRef::Name(name) => {
                let map = if name.starts_with('_') {
                    &self.global
                } else {
                    &self.scope().named
                };
                map.get(name)
                    .copied()
                    .ok_or_else(|| ErrorKind::UndefinedParameter { name: name.clone() })
            }
        }
    }

    /// A predefined named parameter's value.
    fn predefined(&self, name: &str) -> Result<f64, ErrorKind> {
        if let Some(k) = PREDEFINED.iter().position(|n| *n == name) {
            return Ok(self.predefined[k]);
        }
        match name {
            "_value" => Ok(self.return_value),
            "_value_returned" => Ok(if self.value_returned { 1.0 } else { 0.0 }),
            "_call_level" => Ok((self.scopes.len() - 1) as f64),
            _ => Err(ErrorKind::Unsupported {
                what: format!("predefined parameter #<{name}>"),
                reason: "it holds state this front end does not keep (version, coolant, overrides, pockets, A/B/C/U/V/W)",
            }),
        }
    }

    /// Sets the values the kept predefined named parameters read as, in the order of
    /// [`PREDEFINED`].
    pub fn set_predefined(&mut self, values: [f64; PREDEFINED.len()]) {
        self.predefined = values;
    }

    /// A `return` or `endsub`, with its value if it gave one (`#<_value>`,
    /// `#<_value_returned>`).
    pub fn set_returned(&mut self, value: Option<f64>) {
        self.value_returned = value.is_some();
        if let Some(v) = value {
            self.return_value = v;
        }
    }

    /// Sets the value a read-only system parameter reads as.
    pub fn set_system(&mut self, n: u32, value: f64) {
        self.system.insert(n, value);
    }

    /// Whether a named parameter is defined (`EXISTS`).
    pub fn exists(&self, name: &str) -> bool {
        if name.starts_with('_') {
            is_predefined(name) || self.global.contains_key(name)
        } else {
            self.scope().named.contains_key(name)
        }
    }

    /// Sets a parameter.
    pub fn set(&mut self, r: &ParamRef, value: f64) -> Result<(), ErrorKind> {
        match r {
            ParamRef::Number(n @ 1..=30) => self.scope_mut().locals[*n as usize - 1] = value,
            ParamRef::Number(n) if *n <= MAX_USER_PARAMETER => {
                self.numbered.insert(*n, value);
            }
            ParamRef::Number(n) => return Err(system_parameter(*n)),
            ParamRef::Name(name) if name.starts_with('_') && is_predefined(name) => {
                return Err(ErrorKind::ReadOnlyParameter { name: name.clone() });
            }
            ParamRef::Name(name) => {
                let map = if name.starts_with('_') {
                    &mut self.global
                } else {
                    &mut self.scope_mut().named
                };
                if map.len() >= MAX_NAMED_PARAMETERS && !map.contains_key(name) {
                    return Err(ErrorKind::TooManyParameters {
                        max: MAX_NAMED_PARAMETERS,
                    });
                }
                map.insert(name.clone(), value);
            }
        }
        Ok(())
    }

    /// What lives on into the next interpretation on the machine (`gcode::Carry`): the
    /// numbered parameters, the named globals, the main program's scope and the last return
    /// value; not the call scopes, nor the system and predefined values (the next
    /// interpreter sets them from its own state).
    pub fn carried(&self) -> Params {
        Params {
            numbered: self.numbered.clone(),
            global: self.global.clone(),
            scopes: vec![self.scopes.first().cloned().unwrap_or_else(Scope::new)],
            system: HashMap::new(),
            predefined: [0.0; PREDEFINED.len()],
            return_value: self.return_value,
            value_returned: self.value_returned,
        }
    }

    /// Enters a subroutine: new locals, `#1`… set to the call's arguments.
    pub fn push_scope(&mut self, args: &[f64]) {
        let mut scope = Scope::new();
        for (slot, value) in scope.locals.iter_mut().zip(args) {
            *slot = *value;
        }
        self.scopes.push(scope);
    }

    /// Leaves a subroutine (the main program's scope stays).
    pub fn pop_scope(&mut self) {
        if self.scopes.len() > 1 {
            self.scopes.pop();
        }
    }
}

fn system_parameter(n: u32) -> ErrorKind {
    ErrorKind::Unsupported {
        what: format!("system parameter #{n}"),
        reason: "of LinuxCNC's system parameters (#5000 and above), these are kept, read-only: #5070, #5161-#5163, #5181-#5183, #5210-#5213, #5220, #5221-#5223 and #5230 per work system (+20 each), #5399, #5400-#5403, #5410, #5420-#5422, #5599",
    }
}

fn syntax(col: usize, expected: &'static str) -> ExprError {
    (col, ErrorKind::ExpressionSyntax { expected })
}

fn skip_blanks(chars: &[char], i: &mut usize) {
    while chars.get(*i).is_some_and(|c| *c == ' ' || *c == '\t') {
        *i += 1;
    }
}

/// Reads a parameter reference at `*i` (on the `#`).
pub(super) fn param_ref(
    chars: &[char],
    i: &mut usize,
    params: &Params,
    depth: usize,
) -> Result<ParamRef, ExprError> {
    let col = *i + 1;
    if depth > MAX_NESTING {
        return Err((col, ErrorKind::ExpressionTooDeep { max: MAX_NESTING }));
    }
    *i += 1;
    skip_blanks(chars, i);
    if chars.get(*i) == Some(&'<') {
        let start = *i + 1;
        let mut j = start;
        while chars.get(j).is_some_and(|c| *c != '>') {
            j += 1;
        }
        if chars.get(j).is_none() {
            return Err(syntax(col, "'>' closing the parameter name"));
        }
        let name: String = chars
            .get(start..j)
            .unwrap_or_default()
            .iter()
            .filter(|c| !c.is_whitespace())
            .flat_map(|c| c.to_lowercase())
            .collect();
        if name.is_empty() {
            return Err(syntax(col, "a parameter name between '<' and '>'"));
        }
        *i = j + 1;
        return Ok(ParamRef::Name(name));
    }
    let value = real_value(chars, i, params, depth + 1, '#')?;
    let n = value.round();
    if (value - n).abs() > 1e-4 || !(1.0..=1e6).contains(&n) {
        return Err((col, ErrorKind::ParameterNumber { value }));
    }
    // In 1..=1e6: exact.
    Ok(ParamRef::Number(n as u32))
}

/// Reads a value at `*i` (blanks first allowed): a number, parameter, expression, function or
/// signed value. `letter` names the word in messages.
pub(super) fn real_value(
    chars: &[char],
    i: &mut usize,
    params: &Params,
    depth: usize,
    letter: char,
) -> Result<f64, ExprError> {
    skip_blanks(chars, i);
    let col = *i + 1;
    if depth > MAX_NESTING {
        return Err((col, ErrorKind::ExpressionTooDeep { max: MAX_NESTING }));
    }
    let value = match chars.get(*i) {
        Some('[') => expression(chars, i, params, depth + 1)?,
        Some('#') => {
            let r = param_ref(chars, i, params, depth + 1)?;
            params.get(&r).map_err(|k| (col, k))?
        }
        // A sign before a parameter, expression or function; before digits it is the number's.
        Some(c @ ('+' | '-'))
            if chars
                .get(*i + 1)
                .is_some_and(|d| *d == '#' || *d == '[' || d.is_ascii_alphabetic()) =>
        {
            let sign = if *c == '-' { -1.0 } else { 1.0 };
            *i += 1;
            sign * real_value(chars, i, params, depth + 1, letter)?
        }
        Some(c) if c.is_ascii_digit() || matches!(c, '+' | '-' | '.') => number(chars, i, letter)?,
        Some(c) if c.is_ascii_alphabetic() => function(chars, i, params, depth + 1, letter)?,
        _ => return Err((col, ErrorKind::ExpectedNumber { letter })),
    };
    if !value.is_finite() {
        return Err((
            col,
            ErrorKind::MathDomain {
                what: "a result that is not finite",
            },
        ));
    }
    Ok(value)
}

/// A plain number `[+-]digits[.digits]`.
///
/// This runs for every number of every line, so the common case builds no string: when the
/// digits, read as an integer, are at most 2^53 and there are at most 22 decimals, the integer
/// and the power of ten are both exact and one IEEE division rounds correctly, to the value
/// `str::parse` gives (Clinger's fast path, which it takes too). Other numbers go to it.
#[inline]
fn number(chars: &[char], i: &mut usize, letter: char) -> Result<f64, ExprError> {
    let col = *i + 1;
    let start = *i;
    let mut j = *i;
    let negative = chars.get(j) == Some(&'-');
    if matches!(chars.get(j), Some('+' | '-')) {
        j += 1;
    }
    // The token runs over every digit, point and sign so that "1.2.3", "1-2" and "--1" are
    // reported whole as malformed rather than as a stray character after a valid prefix.
    let (mut digits, mut dots, mut signs) = (0usize, 0usize, 0usize);
    let (mut mantissa, mut decimals, mut exact) = (0u64, 0usize, true);
    while let Some(&c) = chars.get(j) {
        match c {
            '0'..='9' => {
                digits += 1;
                let d = u64::from(c) - u64::from('0');
                match mantissa.checked_mul(10).and_then(|m| m.checked_add(d)) {
                    Some(m) if m <= 1 << 53 => mantissa = m,
                    _ => exact = false,
                }
                decimals += usize::from(dots > 0);
            }
            '.' => dots += 1,
            // In a word (`X1-2`) a sign inside the number is malformed; after `#` or inside
            // an expression it is the next operator.
            '+' | '-' if letter.is_ascii_alphabetic() => signs += 1,
            _ => break,
        }
        j += 1;
    }
    *i = j;
    if digits > 0
        && dots <= 1
        && signs == 0
        && exact
        && let Some(power) = POWERS_OF_TEN.get(decimals)
    {
        // Exact: the mantissa is at most 2^53. (No division for a whole number: G and M
        // codes, most F words.)
        let value = if decimals == 0 {
            mantissa as f64
        } else {
            mantissa as f64 / power
        };
        return Ok(if negative { -value } else { value });
    }
    let text: String = chars.get(start..j).unwrap_or_default().iter().collect();
    if digits == 0 || dots > 1 || signs > 0 {
        return Err((col, ErrorKind::MalformedNumber { letter, text }));
    }
    text.parse::<f64>()
        .map_err(|_| (col, ErrorKind::MalformedNumber { letter, text }))
}

/// Exact powers of ten as `f64` (10^22 is the largest that is).
const POWERS_OF_TEN: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// `[expression]` at `*i` (on the `[`).
fn expression(
    chars: &[char],
    i: &mut usize,
    params: &Params,
    depth: usize,
) -> Result<f64, ExprError> {
    let col = *i + 1;
    *i += 1;
    let value = binary(chars, i, params, depth, 0)?;
    skip_blanks(chars, i);
    if chars.get(*i) != Some(&']') {
        return Err(syntax(
            if *i < chars.len() { *i + 1 } else { col },
            "an operator or ']' closing the expression",
        ));
    }
    *i += 1;
    Ok(value)
}

#[derive(Clone, Copy)]
enum Op {
    Pow,
    Mul,
    Div,
    Mod,
    Add,
    Sub,
    Eq,
    Ne,
    Gt,
    Ge,
    Lt,
    Le,
    And,
    Or,
    Xor,
}

impl Op {
    fn precedence(self) -> u8 {
        match self {
            Op::Pow => 4,
            Op::Mul | Op::Div | Op::Mod => 3,
            Op::Add | Op::Sub => 2,
            Op::Eq | Op::Ne | Op::Gt | Op::Ge | Op::Lt | Op::Le => 1,
            Op::And | Op::Or | Op::Xor => 0,
        }
    }
}

/// The operator at `*i`, if any, and the index after it.
fn peek_op(chars: &[char], i: usize) -> Option<(Op, usize)> {
    match chars.get(i)? {
        '*' if chars.get(i + 1) == Some(&'*') => Some((Op::Pow, i + 2)),
        '*' => Some((Op::Mul, i + 1)),
        '/' => Some((Op::Div, i + 1)),
        '+' => Some((Op::Add, i + 1)),
        '-' => Some((Op::Sub, i + 1)),
        c if c.is_ascii_alphabetic() => {
            let mut j = i;
            while chars.get(j).is_some_and(|c| c.is_ascii_alphabetic()) {
                j += 1;
            }
            let word: String = chars
                .get(i..j)?
                .iter()
                .map(|c| c.to_ascii_uppercase())
                .collect();
            let op = match word.as_str() {
                "MOD" => Op::Mod,
                "EQ" => Op::Eq,
                "NE" => Op::Ne,
                "GT" => Op::Gt,
                "GE" => Op::Ge,
                "LT" => Op::Lt,
                "LE" => Op::Le,
                "AND" => Op::And,
                "OR" => Op::Or,
                "XOR" => Op::Xor,
                _ => return None,
            };
            Some((op, j))
        }
        _ => None,
    }
}

/// Precedence climbing: operands and operators of precedence ≥ `min`, left to right.
fn binary(
    chars: &[char],
    i: &mut usize,
    params: &Params,
    depth: usize,
    min: u8,
) -> Result<f64, ExprError> {
    let mut left = real_value(chars, i, params, depth + 1, '[')?;
    loop {
        skip_blanks(chars, i);
        let col = *i + 1;
        let Some((op, next)) = peek_op(chars, *i) else {
            return Ok(left);
        };
        if op.precedence() < min {
            return Ok(left);
        }
        *i = next;
        let right = binary(chars, i, params, depth + 1, op.precedence() + 1)?;
        left = apply(op, left, right).map_err(|k| (col, k))?;
    }
}

fn truth(x: f64) -> bool {
    x != 0.0
}

fn flag(b: bool) -> f64 {
    if b { 1.0 } else { 0.0 }
}

fn apply(op: Op, a: f64, b: f64) -> Result<f64, ErrorKind> {
    let value = match op {
        Op::Pow => {
            if a < 0.0 && b.fract() != 0.0 {
                return Err(ErrorKind::MathDomain {
                    what: "a negative number to a fractional power",
                });
            }
            a.powf(b)
        }
        Op::Mul => a * b,
        Op::Div | Op::Mod if b == 0.0 => return Err(ErrorKind::DivisionByZero),
        Op::Div => a / b,
        // LinuxCNC: the result has the sign of the divisor's... of `fmod`, made non-negative.
        Op::Mod => {
            let r = a % b;
            if r < 0.0 { r + b.abs() } else { r }
        }
        Op::Add => a + b,
        Op::Sub => a - b,
        Op::Eq => flag(a == b),
        Op::Ne => flag(a != b),
        Op::Gt => flag(a > b),
        Op::Ge => flag(a >= b),
        Op::Lt => flag(a < b),
        Op::Le => flag(a <= b),
        Op::And => flag(truth(a) && truth(b)),
        Op::Or => flag(truth(a) || truth(b)),
        Op::Xor => flag(truth(a) != truth(b)),
    };
    if value.is_finite() {
        Ok(value)
    } else {
        Err(ErrorKind::MathDomain {
            what: "a result that is not finite",
        })
    }
}

/// The functions of [`function`], by name.
const FUNCTIONS: [&str; 14] = [
    "ABS", "ACOS", "ASIN", "ATAN", "COS", "SIN", "TAN", "EXP", "FIX", "FUP", "ROUND", "LN", "SQRT",
    "EXISTS",
];

/// A function call at `*i` (on its name), as the value of `letter`'s word.
fn function(
    chars: &[char],
    i: &mut usize,
    params: &Params,
    depth: usize,
    letter: char,
) -> Result<f64, ExprError> {
    let col = *i + 1;
    let start = *i;
    while chars.get(*i).is_some_and(|c| c.is_ascii_alphabetic()) {
        *i += 1;
    }
    let name: String = chars
        .get(start..*i)
        .unwrap_or_default()
        .iter()
        .map(|c| c.to_ascii_uppercase())
        .collect();
    let end = *i;
    skip_blanks(chars, i);
    if chars.get(*i) != Some(&'[') {
        // Say what the letters were taken for: `FOO` is F with the value `OO`.
        return Err((
            col,
            if FUNCTIONS.contains(&name.as_str()) {
                ErrorKind::FunctionWithoutBracket { letter, name }
            } else {
                ErrorKind::NotANumber {
                    letter,
                    text: chars.get(start..end).unwrap_or_default().iter().collect(),
                }
            },
        ));
    }
    if name == "EXISTS" {
        *i += 1;
        skip_blanks(chars, i);
        if chars.get(*i) != Some(&'#') {
            return Err(syntax(*i + 1, "#<name> inside EXISTS[...]"));
        }
        let r = param_ref(chars, i, params, depth + 1)?;
        skip_blanks(chars, i);
        if chars.get(*i) != Some(&']') {
            return Err(syntax(*i + 1, "']' closing EXISTS[...]"));
        }
        *i += 1;
        return Ok(match r {
            ParamRef::Name(n) => flag(params.exists(&n)),
            ParamRef::Number(_) => 1.0,
        });
    }
    let arg = expression(chars, i, params, depth + 1)?;
    let domain = |what: &'static str| Err((col, ErrorKind::MathDomain { what }));
    let value = match name.as_str() {
        "ABS" => arg.abs(),
        "ACOS" | "ASIN" if !(-1.0..=1.0).contains(&arg) => {
            return domain("ACOS or ASIN of a value outside [-1, 1]");
        }
        "ACOS" => arg.acos().to_degrees(),
        "ASIN" => arg.asin().to_degrees(),
        "ATAN" => {
            skip_blanks(chars, i);
            if chars.get(*i) != Some(&'/') {
                return Err(syntax(*i + 1, "'/' in ATAN[y]/[x]"));
            }
            *i += 1;
            skip_blanks(chars, i);
            if chars.get(*i) != Some(&'[') {
                return Err(syntax(*i + 1, "'[' in ATAN[y]/[x]"));
            }
            let x = expression(chars, i, params, depth + 1)?;
            arg.atan2(x).to_degrees()
        }
        "COS" => arg.to_radians().cos(),
        "SIN" => arg.to_radians().sin(),
        "TAN" => arg.to_radians().tan(),
        "EXP" => arg.exp(),
        "FIX" => arg.floor(),
        "FUP" => arg.ceil(),
        "ROUND" => arg.round(),
        "LN" if arg <= 0.0 => return domain("LN of a value that is not positive"),
        "LN" => arg.ln(),
        "SQRT" if arg < 0.0 => return domain("SQRT of a negative value"),
        "SQRT" => arg.sqrt(),
        _ => return Err((col, ErrorKind::UnknownFunction { name })),
    };
    Ok(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn eval_with(text: &str, params: &Params) -> Result<f64, ExprError> {
        let chars: Vec<char> = text.chars().collect();
        let mut i = 0;
        let v = real_value(&chars, &mut i, params, 0, 'X')?;
        assert_eq!(i, chars.len(), "{text}: not all read");
        Ok(v)
    }

    fn eval(text: &str) -> f64 {
        eval_with(text, &Params::default()).unwrap()
    }

    /// The fast path of plain numbers gives bit for bit what `str::parse` gives (sign of zero
    /// included), and stands aside where it could not.
    #[test]
    fn plain_numbers_parse_as_the_standard_parser_does() {
        let mut tokens: Vec<String> = [
            "0",
            "-0",
            "+0",
            "-0.0",
            ".5",
            "5.",
            "-.5",
            "+1.25",
            "007",
            "0.1",
            "0.3",
            "1.0005",
            "123.4567",
            "9007199254740992",
            "9007199254740993",
            "0.0000000000000000000001",
            "0.00000000000000000000001",
            "99999999999999999999",
            "1.7976931348623157",
        ]
        .iter()
        .map(|t| t.to_string())
        .collect();
        // Seeded: the tiny bench's kind of numbers, and long ones that leave the fast path.
        let mut x: u64 = 0x2545_f491_4f6c_dd1d;
        for _ in 0..20_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let decimals = (x % 19) as usize;
            let whole = (x >> 20) % 100_000;
            let frac = (x >> 5) % 10u64.pow(decimals.min(12) as u32);
            let sign = ["", "-", "+"][(x % 3) as usize];
            tokens.push(if decimals == 0 {
                format!("{sign}{whole}")
            } else {
                format!("{sign}{whole}.{frac:0decimals$}")
            });
        }
        for t in &tokens {
            let chars: Vec<char> = t.chars().collect();
            let mut i = 0;
            match (number(&chars, &mut i, 'X'), t.parse::<f64>()) {
                (Ok(a), Ok(b)) => assert_eq!(a.to_bits(), b.to_bits(), "{t}"),
                (a, b) => panic!("{t}: {a:?} {b:?}"),
            }
            assert_eq!(i, chars.len(), "{t}: not all read");
        }
    }

    #[test]
    fn arithmetic_and_precedence() {
        assert_eq!(eval("[1 + 2 * 3]"), 7.0);
        assert_eq!(eval("[[1 + 2] * 3]"), 9.0);
        assert_eq!(eval("[2 ** 3 * 2]"), 16.0);
        assert_eq!(eval("[10 - 4 - 3]"), 3.0);
        assert_eq!(eval("[7 MOD 3]"), 1.0);
        assert_eq!(eval("[-7 mod 3]"), 2.0);
        assert_eq!(eval("[1 lt 2 and 3 gt 2]"), 1.0);
        assert_eq!(eval("[1 + 1 EQ 2]"), 1.0);
        assert_eq!(eval("-[2]"), -2.0);
        assert_eq!(eval("[-.5*2]"), -1.0);
        assert!((eval("sin[30]") - 0.5).abs() < 1e-12);
        assert!((eval("ATAN[1]/[1]") - 45.0).abs() < 1e-12);
        assert_eq!(
            eval("[SQRT[16] + ABS[-1] + FIX[1.7] + FUP[1.2] + ROUND[2.5]]"),
            11.0
        );
    }

    #[test]
    fn parameters_and_scopes() {
        let mut p = Params::default();
        p.set(&ParamRef::Number(1), 2.0).unwrap();
        p.set(&ParamRef::Number(100), 3.0).unwrap();
        p.set(&ParamRef::Name("scale".into()), 0.5).unwrap();
        p.set(&ParamRef::Name("_g".into()), 7.0).unwrap();
        assert_eq!(eval_with("[#1 * #100 + #<Sca le>]", &p).unwrap(), 6.5);
        assert_eq!(eval_with("##1", &p).unwrap(), 0.0);
        assert_eq!(eval_with("#[#1 * 50]", &p).unwrap(), 3.0);
        assert_eq!(eval_with("EXISTS[#<scale>]", &p).unwrap(), 1.0);
        p.push_scope(&[9.0]);
        assert_eq!(eval_with("#1", &p).unwrap(), 9.0);
        assert_eq!(eval_with("#100", &p).unwrap(), 3.0);
        assert_eq!(eval_with("#<_g>", &p).unwrap(), 7.0);
        assert_eq!(eval_with("EXISTS[#<scale>]", &p).unwrap(), 0.0);
        assert!(eval_with("#<scale>", &p).is_err());
        p.pop_scope();
        assert_eq!(eval_with("#1", &p).unwrap(), 2.0);
    }

    #[test]
    fn predefined_named_parameters_are_read_only_and_exist() {
        let mut p = Params::default();
        let mut values = [0.0; PREDEFINED.len()];
        values[PREDEFINED.iter().position(|n| *n == "_x").unwrap()] = 7.0;
        p.set_predefined(values);
        assert_eq!(eval_with("[#<_x> + 1]", &p).unwrap(), 8.0);
        assert_eq!(
            eval_with("[EXISTS[#<_x>] + EXISTS[#<_mist>]]", &p).unwrap(),
            2.0
        );
        assert_eq!(
            p.set(&ParamRef::Name("_x".into()), 1.0),
            Err(ErrorKind::ReadOnlyParameter { name: "_x".into() })
        );
        assert!(p.get(&ParamRef::Name("_mist".into())).is_err());
        assert_eq!(
            eval_with("[#<_value_returned> + #<_call_level>]", &p).unwrap(),
            0.0
        );
        p.push_scope(&[]);
        p.set_returned(Some(4.0));
        assert_eq!(
            eval_with("[#<_value> + #<_value_returned> + #<_call_level>]", &p).unwrap(),
            6.0
        );
        // A global of one's own is no predefined one.
        p.set(&ParamRef::Name("_xx".into()), 2.0).unwrap();
        assert_eq!(eval_with("#<_xx>", &p).unwrap(), 2.0);
    }

    #[test]
    fn errors_have_columns() {
        let e = |t: &str| eval_with(t, &Params::default()).unwrap_err();
        assert_eq!(e("[1/0]").1, ErrorKind::DivisionByZero);
        assert_eq!(e("[1/0]").0, 3);
        assert_eq!(e("SQRT[-1]").0, 1);
        assert_eq!(e("[1 + ]").1, ErrorKind::ExpectedNumber { letter: '[' });
        assert_eq!(e("[1 2]").0, 4);
        assert_eq!(
            e("#<nope>").1,
            ErrorKind::UndefinedParameter {
                name: "nope".into()
            }
        );
        assert!(matches!(e("#5220").1, ErrorKind::Unsupported { .. }));
        assert_eq!(
            e("FOO[1]").1,
            ErrorKind::UnknownFunction { name: "FOO".into() }
        );
        // Every listed function is one (so the messages about them hold).
        for name in FUNCTIONS {
            let text = match name {
                "ATAN" => "ATAN[1]/[1]".to_string(),
                "EXISTS" => "EXISTS[#<a>]".to_string(),
                _ => format!("{name}[1]"),
            };
            assert!(eval_with(&text, &Params::default()).is_ok(), "{text}");
        }
        let deep = format!("{}1{}", "[".repeat(500), "]".repeat(500));
        assert_eq!(
            e(&deep).1,
            ErrorKind::ExpressionTooDeep { max: MAX_NESTING }
        );
        assert!(matches!(e("[10 ** 400]").1, ErrorKind::MathDomain { .. }));
    }
}
