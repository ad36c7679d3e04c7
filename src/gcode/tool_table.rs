//! Tool table: tool number → radius and length. [`crate::config::tool_table`] loads it from
//! TOML:
//!
//! ```toml
//! [[tool]]
//! number = 1          # T, H and D words refer to it; 0 is "no tool" and cannot be listed
//! radius_mm = 2.0     # for cutter compensation (G41/G42 D1)
//! length_mm = 50.0    # for tool length compensation (G43 H1), along the tool axis
//! description = "4 mm flat end mill"   # optional
//! ```
//!
use std::collections::BTreeMap;

/// Largest tool number (LinuxCNC's limit).
pub const MAX_TOOL_NUMBER: u32 = 99_999;

/// Largest tool radius or length magnitude accepted, mm.
pub const MAX_TOOL_SIZE_MM: f64 = 10_000.0;

/// One tool's offsets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tool {
    /// Radius for cutter compensation; negative puts the tool on the other side under G41/G42
    /// (a negative diameter in LinuxCNC's table).
    pub radius_mm: f64,
    /// Length along the tool axis for length compensation (may be negative).
    pub length_mm: f64,
}

impl Tool {
    /// Tool 0, "no tool": radius and length 0.
    pub const NONE: Tool = Tool {
        radius_mm: 0.0,
        length_mm: 0.0,
    };
}

/// Tool number → offsets. Tool 0 is always "no tool" ([`Tool::NONE`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ToolTable {
    tools: BTreeMap<u32, Tool>,
}

impl ToolTable {
    /// An empty table.
    pub fn new() -> ToolTable {
        ToolTable::default()
    }

    /// The tool with this number: [`Tool::NONE`] for 0, `None` if it is not in the table.
    pub fn get(&self, number: u32) -> Option<Tool> {
        if number == 0 {
            return Some(Tool::NONE);
        }
        self.tools.get(&number).copied()
    }

    /// Adds or replaces a tool (number 0 is ignored: it is always "no tool"); returns the
    /// previous entry.
    pub fn insert(&mut self, number: u32, tool: Tool) -> Option<Tool> {
        if number == 0 {
            return None;
        }
        self.tools.insert(number, tool)
    }

    /// The listed tools in number order (tool 0 is not listed).
    pub fn iter(&self) -> impl Iterator<Item = (u32, Tool)> + '_ {
        self.tools.iter().map(|(n, t)| (*n, *t))
    }

    /// Number of listed tools.
    pub fn len(&self) -> usize {
        self.tools.len()
    }

    /// Whether no tool is listed.
    pub fn is_empty(&self) -> bool {
        self.tools.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn insert_replaces_and_ignores_tool_zero() {
        let mut t = ToolTable::new();
        assert!(t.is_empty());
        let tool = Tool {
            radius_mm: 1.0,
            length_mm: 2.0,
        };
        assert_eq!(t.insert(5, tool), None);
        assert_eq!(t.insert(0, tool), None);
        assert_eq!(t.get(0), Some(Tool::NONE));
        assert_eq!(t.iter().collect::<Vec<_>>(), vec![(5, tool)]);
    }
}
