//! The layer check: no module under `src/` imports a higher layer.
//!
//! The order is written once, in [`LAYERS`], lowest first (it is the one `src/lib.rs`
//! documents). Every `crate::NAME` path in a module's code (comments and in-file `#[cfg(test)]`
//! modules excluded, as are `tests.rs` files: tests may use any layer to build their fixtures)
//! must name a module of the same layer or a lower one. A new top-level module must be placed in
//! the list before this test passes.

use std::path::{Path, PathBuf};

/// The layers, lowest first. Modules in one group may import each other.
const LAYERS: &[&[&str]] = &[
    &["files"],
    &["bus"],
    &["canopen"],
    &["cia402"],
    &["gcode"],
    &["compensation"],
    &["planner"],
    &["interpolator"],
    &["config"],
    &["eds"],
    &["master"],
    &["rt"],
    &["sim"],
    &["gateway"],
    &["plot", "optimize"],
    &["offline"],
    &["commands"],
    &["fuzzing"],
];

fn layer(module: &str) -> Option<usize> {
    LAYERS.iter().position(|group| group.contains(&module))
}

/// One import of a higher layer: where, and what.
#[derive(Debug, PartialEq)]
struct Violation {
    file: PathBuf,
    line: usize,
    module: String,
    imports: String,
}

/// The code lines of a file with comments and in-file `#[cfg(test)] mod … { … }` blocks blanked
/// (so that line numbers stay right).
fn code_lines(text: &str) -> Vec<String> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::with_capacity(lines.len());
    let mut i = 0;
    while i < lines.len() {
        let trimmed = lines[i].trim_start();
        if trimmed.starts_with("#[cfg(test)]")
            && let Some(next) = lines.get(i + 1)
            && next.trim_start().starts_with("mod ")
            && next.trim_end().ends_with('{')
        {
            let indent = next.len() - next.trim_start().len();
            let close = format!("{}}}", " ".repeat(indent));
            let end = lines[i + 2..]
                .iter()
                .position(|l| l.trim_end() == close)
                .map_or(lines.len(), |p| i + 2 + p);
            for _ in i..=end.min(lines.len() - 1) {
                out.push(String::new());
            }
            i = end + 1;
            continue;
        }
        let code = match lines[i].find("//") {
            Some(at) => &lines[i][..at],
            None => lines[i],
        };
        out.push(code.to_string());
        i += 1;
    }
    out
}

/// The top-level modules a file's code names through `crate::`, with their line numbers
/// (`crate::a::b`, and every item of `crate::{a, b::c}` on one line).
fn crate_paths(lines: &[String]) -> Vec<(usize, String)> {
    let mut found = Vec::new();
    for (n, line) in lines.iter().enumerate() {
        let mut rest = line.as_str();
        while let Some(at) = rest.find("crate::") {
            let before = &rest[..at];
            rest = &rest[at + "crate::".len()..];
            // `$crate::` and `other_crate::` are not ours.
            if before
                .chars()
                .last()
                .is_some_and(|c| c.is_alphanumeric() || c == '_' || c == '$')
            {
                continue;
            }
            if let Some(group) = rest.strip_prefix('{') {
                let group = group.split('}').next().unwrap_or("");
                for item in group.split(',') {
                    let name: String = item
                        .trim()
                        .chars()
                        .take_while(|c| c.is_alphanumeric() || *c == '_')
                        .collect();
                    if !name.is_empty() {
                        found.push((n + 1, name));
                    }
                }
            } else {
                let name: String = rest
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                found.push((n + 1, name));
            }
        }
    }
    found
}

fn check_text(file: &Path, module: &str, text: &str) -> Vec<Violation> {
    let Some(own) = layer(module) else {
        return Vec::new();
    };
    crate_paths(&code_lines(text))
        .into_iter()
        .filter(|(_, name)| layer(name).is_some_and(|l| l > own))
        .map(|(line, name)| Violation {
            file: file.to_path_buf(),
            line,
            module: module.to_string(),
            imports: name,
        })
        .collect()
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("src/ is readable") {
        let path = entry.expect("directory entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

#[test]
fn no_module_imports_a_higher_layer() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    let mut unplaced = Vec::new();
    let mut violations = Vec::new();
    for file in &files {
        let rel = file.strip_prefix(&src).unwrap();
        let first = rel
            .components()
            .next()
            .unwrap()
            .as_os_str()
            .to_string_lossy();
        let module = first.trim_end_matches(".rs").to_string();
        if module == "lib" || module == "main" {
            continue;
        }
        if layer(&module).is_none() {
            unplaced.push(module.clone());
            continue;
        }
        if file.file_name().is_some_and(|n| n == "tests.rs") {
            continue;
        }
        let text = std::fs::read_to_string(file).unwrap();
        violations.extend(check_text(rel, &module, &text));
    }
    unplaced.dedup();
    assert!(
        unplaced.is_empty(),
        "modules not placed in LAYERS (tests/layers.rs): {unplaced:?}"
    );
    let report: Vec<String> = violations
        .iter()
        .map(|v| {
            format!(
                "src/{}:{}: `{}` (layer {}) imports `{}` (layer {})",
                v.file.display(),
                v.line,
                v.module,
                layer(&v.module).unwrap(),
                v.imports,
                layer(&v.imports).unwrap()
            )
        })
        .collect();
    assert!(
        report.is_empty(),
        "imports of a higher layer:\n{}",
        report.join("\n")
    );
}

#[test]
fn the_scanner_sees_paths_groups_and_skips_comments_and_tests() {
    let text = "use crate::bus::Frame;\n\
                use crate::{gateway, files::read_text};\n\
                // crate::offline in a comment\n\
                let x = crate::sim::SimDrive::new(); // and crate::commands here\n\
                macro_rules! m { () => { $crate::offline::f() } }\n\
                #[cfg(test)]\n\
                mod tests {\n\
                    use crate::offline;\n\
                }\n\
                use crate::eds;\n";
    let found = check_text(Path::new("canopen/x.rs"), "canopen", text);
    let got: Vec<(usize, &str)> = found.iter().map(|v| (v.line, v.imports.as_str())).collect();
    assert_eq!(got, vec![(2, "gateway"), (4, "sim"), (10, "eds")]);
}
