//! Loading a tool table ([`ToolTable`]) from TOML:
//!
//! ```toml
//! [[tool]]
//! number = 1          # T, H and D words refer to it; 0 is "no tool" and cannot be listed
//! radius_mm = 2.0     # for cutter compensation (G41/G42 D1)
//! length_mm = 50.0    # for tool length compensation (G43 H1), along the tool axis
//! description = "4 mm flat end mill"   # optional
//! ```
//!
//! Loading is strict like every configuration file: unknown keys are errors, and every error
//! names the file, the table (`tool 3`) and the key. The table itself is G-code's
//! ([`crate::gcode::ToolTable`]); only the reading is here, so that `gcode` needs no `config`.

use std::path::Path;

use serde::Deserialize;

use super::{ConfigError, parse_toml};
use crate::gcode::{MAX_TOOL_NUMBER, MAX_TOOL_SIZE_MM, Tool, ToolTable};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    #[serde(default)]
    tool: Vec<ToolEntry>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ToolEntry {
    number: i64,
    radius_mm: f64,
    length_mm: f64,
    #[serde(default)]
    #[allow(dead_code)]
    description: Option<String>,
}

impl ToolTable {
    /// Reads and checks a tool table file.
    pub fn load(path: &Path) -> Result<ToolTable, ConfigError> {
        let text = crate::files::read_text(path, crate::files::MAX_CONFIG_BYTES)?;
        ToolTable::parse(path, &text)
    }

    /// Checks a tool table given as text; `path` names it in errors.
    pub fn parse(path: &Path, text: &str) -> Result<ToolTable, ConfigError> {
        let file: File = parse_toml(path, text)?;
        let mut table = ToolTable::new();
        for (index, entry) in file.tool.iter().enumerate() {
            let invalid = |table: String, key: &str, message: String| ConfigError::Invalid {
                file: path.to_path_buf(),
                table,
                key: key.to_owned(),
                message,
            };
            let number = u32::try_from(entry.number)
                .ok()
                .filter(|n| (1..=MAX_TOOL_NUMBER).contains(n))
                .ok_or_else(|| {
                    invalid(
                        format!("tool #{}", index + 1),
                        "number",
                        format!(
                            "{} must be an integer from 1 to {MAX_TOOL_NUMBER} (0 is \"no tool\")",
                            entry.number
                        ),
                    )
                })?;
            let name = format!("tool {number}");
            // A negative radius is allowed, as a negative diameter in LinuxCNC's table: G41/G42
            // then compensate on the other side (a path made for a nominal tool, cut with a
            // smaller one).
            if !(-MAX_TOOL_SIZE_MM..=MAX_TOOL_SIZE_MM).contains(&entry.radius_mm) {
                return Err(invalid(
                    name,
                    "radius_mm",
                    format!(
                        "{} must be from -{MAX_TOOL_SIZE_MM} to {MAX_TOOL_SIZE_MM} mm",
                        entry.radius_mm
                    ),
                ));
            }
            if !(-MAX_TOOL_SIZE_MM..=MAX_TOOL_SIZE_MM).contains(&entry.length_mm) {
                return Err(invalid(
                    name,
                    "length_mm",
                    format!(
                        "{} must be from -{MAX_TOOL_SIZE_MM} to {MAX_TOOL_SIZE_MM} mm",
                        entry.length_mm
                    ),
                ));
            }
            let tool = Tool {
                radius_mm: entry.radius_mm,
                length_mm: entry.length_mm,
            };
            if table.insert(number, tool).is_some() {
                return Err(invalid(
                    name,
                    "number",
                    format!("tool {number} is listed twice"),
                ));
            }
        }
        Ok(table)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<ToolTable, ConfigError> {
        ToolTable::parse(Path::new("t.toml"), text)
    }

    #[test]
    fn the_demo_table_loads() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("dictionaries/tools/demo-tools.toml");
        let t = ToolTable::load(&path).unwrap();
        assert_eq!(
            t.get(1),
            Some(Tool {
                radius_mm: 2.0,
                length_mm: 50.0
            })
        );
        assert!(t.len() >= 3);
        assert_eq!(t.get(0), Some(Tool::NONE));
        assert_eq!(t.get(999), None);
    }

    #[test]
    fn a_negative_radius_loads() {
        // LinuxCNC's tables may hold a negative diameter: G41/G42 swap sides with it.
        let t = parse("[[tool]]\nnumber = 3\nradius_mm = -0.5\nlength_mm = 5\n").unwrap();
        assert_eq!(t.get(3).map(|t| t.radius_mm), Some(-0.5));
    }

    #[test]
    fn errors_name_file_table_and_key() {
        let cases = [
            (
                "[[tool]]\nnumber = 1\nradius_mm = -10001\nlength_mm = 5\n",
                "t.toml: [tool 1] radius_mm: -10001 must be from -10000 to 10000 mm",
            ),
            (
                "[[tool]]\nnumber = 0\nradius_mm = 1\nlength_mm = 5\n",
                "t.toml: [tool #1] number: 0 must be an integer from 1 to 99999 (0 is \"no tool\")",
            ),
            (
                "[[tool]]\nnumber = 2\nradius_mm = 1\nlength_mm = nan\n",
                "t.toml: [tool 2] length_mm: NaN must be from -10000 to 10000 mm",
            ),
            (
                "[[tool]]\nnumber = 2\nradius_mm = 1\nlength_mm = 1\n[[tool]]\nnumber = 2\nradius_mm = 1\nlength_mm = 1\n",
                "t.toml: [tool 2] number: tool 2 is listed twice",
            ),
        ];
        for (text, message) in cases {
            assert_eq!(parse(text).unwrap_err().to_string(), message, "{text}");
        }
        let e = parse("[[tool]]\nnumber = 1\nradius_mm = 1\nlength_mm = 1\ndiameter_mm = 2\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("t.toml: ") && e.contains("diameter_mm"),
            "{e}"
        );
        let e = parse("[tools]\n").unwrap_err().to_string();
        assert!(e.contains("tools"), "{e}");
    }
}
