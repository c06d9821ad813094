//! Machine-tool model (in progress).

use crate::error::Result;

/// A validated machine tool.
#[derive(Debug, Clone)]
pub struct MachineTool {}

impl MachineTool {
    /// Parses and validates machine-tool YAML.
    pub fn from_yaml_str(_text: &str, _file: &str) -> Result<Self> {
        Ok(MachineTool {})
    }
}
