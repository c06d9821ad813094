//! Machine definitions: YAML files are read into strict raw structs
//! (`deny_unknown_fields`), then validated once into an immutable [`Machine`]
//! that the engine shares between threads.

pub mod robot;
pub mod tool;
pub mod yaml;

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// Slot index of each axis letter in an [`AxisVec`]: X Y Z A B C.
pub const AXIS_LETTERS: [u8; 6] = [b'X', b'Y', b'Z', b'A', b'B', b'C'];

/// Commanded axis values in slot order X Y Z A B C. Linear axes in mm, rotary
/// axes in degrees (the unit of programs and observation files).
pub type AxisVec = [f64; 6];

/// Sign of the last motion of each axis (+1 or −1), slot order X Y Z A B C.
pub type DirVec = [i8; 6];

/// Slot of an axis letter (upper case) in an [`AxisVec`].
pub fn axis_slot(letter: u8) -> Option<usize> {
    AXIS_LETTERS
        .iter()
        .position(|&l| l == letter.to_ascii_uppercase())
}

/// Position of the tool tip and direction of the tool axis (unit vector
/// pointing from the tip into the spindle), both in the workpiece frame, mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipPose {
    /// Tool tip position, mm.
    pub pos: nalgebra::Vector3<f64>,
    /// Unit tool-axis direction (tip → spindle).
    pub dir: nalgebra::Vector3<f64>,
}

/// A validated machine: a machine tool or an articulated robot.
#[derive(Debug, Clone)]
pub enum Machine {
    /// A CNC machine tool with linear and rotary axes.
    Tool(tool::MachineTool),
    /// A 6R industrial robot.
    Robot(robot::Robot),
}

/// The machine kinds a file can declare with its top-level `kind` key.
#[derive(Debug, serde::Deserialize)]
struct KindOnly {
    kind: Option<String>,
}

impl Machine {
    /// Loads and validates a machine file. Errors name the file, line and key
    /// path.
    pub fn load(path: &Path) -> Result<Machine> {
        let text = Self::read_text(path)?;
        Self::from_yaml_str(&text, &path.display().to_string())
    }

    /// The text of a machine file, at most [`crate::limits::YAML_MAX_BYTES`]
    /// long with lines of at most [`crate::limits::LINE_MAX_BYTES`]; invalid
    /// UTF-8 is a located error.
    pub fn read_text(path: &Path) -> Result<String> {
        let file = path.display().to_string();
        let bytes = crate::limits::read_file_bounded(path, crate::limits::YAML_MAX_BYTES)?;
        crate::error::utf8_text(&bytes, &file)?;
        Ok(String::from_utf8(bytes).unwrap_or_default())
    }

    /// Parses and validates machine YAML text; `file` names it in errors.
    pub fn from_yaml_str(text: &str, file: &str) -> Result<Machine> {
        let kind: KindOnly = yaml::deserialize(text, file)?;
        match kind.kind.as_deref() {
            Some("machine_tool") => {
                Ok(Machine::Tool(tool::MachineTool::from_yaml_str(text, file)?))
            }
            Some("robot") => Ok(Machine::Robot(robot::Robot::from_yaml_str(text, file)?)),
            Some(other) => Err(yaml::located(
                text,
                file,
                "kind",
                &format!("unknown machine kind `{other}` (expected `machine_tool` or `robot`)"),
            )),
            None => Err(Error::Input(crate::error::Located::new(
                file,
                1,
                1,
                "missing top-level key `kind` (`machine_tool` or `robot`)",
            ))),
        }
    }

    /// Resolves `--machine NAME`: an existing path, or `machines/NAME.yaml`
    /// bundled with the tool (looked up beside the executable's source tree
    /// and in the current directory).
    pub fn resolve(name: &str) -> Result<PathBuf> {
        let direct = PathBuf::from(name);
        if direct.is_file() {
            return Ok(direct);
        }
        let file = if name.ends_with(".yaml") || name.ends_with(".yml") {
            name.to_string()
        } else {
            format!("{name}.yaml")
        };
        let mut candidates = vec![PathBuf::from("machines").join(&file)];
        if let Some(dir) = option_env!("CARGO_MANIFEST_DIR") {
            candidates.push(PathBuf::from(dir).join("machines").join(&file));
        }
        if let Ok(exe) = std::env::current_exe() {
            for anc in exe.ancestors().skip(1).take(4) {
                candidates.push(anc.join("machines").join(&file));
            }
        }
        candidates.into_iter().find(|p| p.is_file()).ok_or_else(|| {
            if direct.exists() {
                Error::Usage(format!("machine `{name}` is not a regular file"))
            } else {
                Error::Usage(format!(
                    "machine `{name}` not found (no such file, and no machines/{file})"
                ))
            }
        })
    }
}
