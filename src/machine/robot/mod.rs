//! Robot model (in progress).

use crate::error::Result;

/// A validated 6R robot.
#[derive(Debug, Clone)]
pub struct Robot {}

impl Robot {
    /// Parses and validates robot YAML.
    pub fn from_yaml_str(_text: &str, _file: &str) -> Result<Self> {
        Ok(Robot {})
    }
}
