//! Machine definitions: YAML files are read into strict raw structs
//! (`deny_unknown_fields`), then validated once into an immutable [`Machine`]
//! that the engine shares between threads. The bundled machine files are
//! part of the binary ([`BUNDLED`]), so `--machine NAME` works wherever the
//! binary runs.

pub mod effects;
pub mod plausibility;
pub mod robot;
pub mod status;
pub mod thermal_start;
pub mod tool;
pub mod yaml;
pub mod yaml_write;

use std::borrow::Cow;
use std::path::{Path, PathBuf};

pub use status::Status;
pub use thermal_start::{MAX_WARM_UP_MIN, ThermalStart};

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

/// The machine kinds a file can declare with its top-level `kind` key:
/// read only for the typed reader's words on a document that is not a
/// mapping.
#[derive(Debug, serde::Deserialize)]
struct KindOnly {
    #[allow(dead_code)]
    kind: Option<String>,
}

impl Machine {
    /// Pose of the measuring instrument in the machine's reference frame
    /// (the file's `measurement_frame`), if given.
    pub fn measurement_frame(&self) -> Option<nalgebra::Isometry3<f64>> {
        match self {
            Machine::Tool(t) => t.measurement_frame().copied(),
            Machine::Robot(r) => r.measurement_frame().copied(),
        }
    }

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
        let bytes =
            crate::limits::read_file_bounded(path, crate::limits::YAML_MAX_BYTES).map_err(|e| {
                match e {
                    Error::Input(at) => Error::Machine(at),
                    other => other,
                }
            })?;
        crate::error::utf8_text(&bytes, &file).map_err(Error::Machine)?;
        Ok(String::from_utf8(bytes).unwrap_or_default())
    }

    /// Parses and validates machine YAML text; `file` names it in errors.
    /// The text is read once ([`yaml::Source::read`]: one syntax tree,
    /// duplicate keys and layouts `calibrate` could not write back refused
    /// with their key path) and validated by the strict loader of its kind.
    pub fn from_yaml_str(text: &str, file: &str) -> Result<Machine> {
        Self::from_source(&yaml::Source::read(text, file)?)
    }

    /// Validates a machine file read by [`yaml::Source::read`].
    pub fn from_source(src: &yaml::Source) -> Result<Machine> {
        let (text, file) = (src.text(), src.file());
        if !src.is_mapping() {
            // The typed reader says what the document is instead.
            src.deserialize::<KindOnly>()?;
        }
        match src.kind() {
            Some("machine_tool") => Ok(Machine::Tool(tool::MachineTool::from_source(src)?)),
            Some("robot") => Ok(Machine::Robot(robot::Robot::from_source(src)?)),
            Some(other) => Err(yaml::located(
                text,
                file,
                "kind",
                &format!("unknown machine kind `{other}` (expected `machine_tool` or `robot`)"),
            )),
            None => Err(Error::Machine(crate::error::Located::new(
                file,
                1,
                1,
                "missing top-level key `kind` (`machine_tool` or `robot`)",
            ))),
        }
    }
}

/// The machine files bundled with postproc, compiled into the binary:
/// (name, text), in name order. `--machine NAME` selects one by name. The
/// robot library (nominal ABB, KUKA and FANUC arms) is described in machines/README.md.
pub const BUNDLED: [(&str, &str); 26] = [
    (
        "abb-crb15000",
        include_str!("../../machines/abb-crb15000.yaml"),
    ),
    ("abb-irb120", include_str!("../../machines/abb-irb120.yaml")),
    (
        "abb-irb1200-0.7",
        include_str!("../../machines/abb-irb1200-0.7.yaml"),
    ),
    (
        "abb-irb1200-0.9",
        include_str!("../../machines/abb-irb1200-0.9.yaml"),
    ),
    ("abb-irb140", include_str!("../../machines/abb-irb140.yaml")),
    (
        "abb-irb1600",
        include_str!("../../machines/abb-irb1600.yaml"),
    ),
    (
        "abb-irb1600-1.2",
        include_str!("../../machines/abb-irb1600-1.2.yaml"),
    ),
    (
        "abb-irb2400",
        include_str!("../../machines/abb-irb2400.yaml"),
    ),
    (
        "abb-irb2600-1.65",
        include_str!("../../machines/abb-irb2600-1.65.yaml"),
    ),
    (
        "abb-irb2600-1.85",
        include_str!("../../machines/abb-irb2600-1.85.yaml"),
    ),
    (
        "abb-irb4600-2.05",
        include_str!("../../machines/abb-irb4600-2.05.yaml"),
    ),
    (
        "abb-irb4600-2.55",
        include_str!("../../machines/abb-irb4600-2.55.yaml"),
    ),
    (
        "abb-irb6640",
        include_str!("../../machines/abb-irb6640.yaml"),
    ),
    (
        "abb-irb6700",
        include_str!("../../machines/abb-irb6700.yaml"),
    ),
    ("afm-r1000", include_str!("../../machines/afm-r1000.yaml")),
    (
        "fanuc-lrmate200id",
        include_str!("../../machines/fanuc-lrmate200id.yaml"),
    ),
    (
        "fanuc-lrmate200id-7l",
        include_str!("../../machines/fanuc-lrmate200id-7l.yaml"),
    ),
    (
        "fanuc-m20ia",
        include_str!("../../machines/fanuc-m20ia.yaml"),
    ),
    (
        "fanuc-r2000ic-165f",
        include_str!("../../machines/fanuc-r2000ic-165f.yaml"),
    ),
    (
        "five-axis-ac",
        include_str!("../../machines/five-axis-ac.yaml"),
    ),
    (
        "head-table-bc",
        include_str!("../../machines/head-table-bc.yaml"),
    ),
    (
        "kuka-kr16-2",
        include_str!("../../machines/kuka-kr16-2.yaml"),
    ),
    (
        "kuka-kr210-r2700-2",
        include_str!("../../machines/kuka-kr210-r2700-2.yaml"),
    ),
    (
        "kuka-kr6-r900-2",
        include_str!("../../machines/kuka-kr6-r900-2.yaml"),
    ),
    (
        "kuka-kr6-r900-sixx",
        include_str!("../../machines/kuka-kr6-r900-sixx.yaml"),
    ),
    (
        "staubli-tx200",
        include_str!("../../machines/staubli-tx200.yaml"),
    ),
];

/// A machine file as a run reads it: a file on disk or a bundled one.
#[derive(Debug, Clone)]
pub struct MachineFile {
    /// How errors name it: the path, or `NAME.yaml (bundled)`.
    pub shown: String,
    /// The file name without folders (`afm-r1000.yaml`), as provenance
    /// records it.
    pub file_name: String,
    /// The path on disk; `None` for a bundled file.
    pub path: Option<PathBuf>,
    /// The YAML text.
    pub text: Cow<'static, str>,
}

impl MachineFile {
    /// Resolves `--machine NAME`: an existing file wins; else the name of a
    /// bundled machine (`afm-r1000`, also spelt `afm-r1000.yaml` or
    /// `machines/afm-r1000.yaml`), whatever the current directory.
    pub fn open(name: &str) -> Result<MachineFile> {
        let direct = Path::new(name);
        if direct.is_file() {
            let text = Machine::read_text(direct)?;
            return Ok(MachineFile {
                shown: direct.display().to_string(),
                file_name: direct
                    .file_name()
                    .map_or_else(|| name.to_string(), |n| n.to_string_lossy().to_string()),
                path: Some(direct.to_path_buf()),
                text: Cow::Owned(text),
            });
        }
        if let Some(file) = Self::bundled(name) {
            return Ok(file);
        }
        if direct.exists() {
            Err(Error::Usage(format!(
                "machine `{name}` is not a regular file"
            )))
        } else {
            let names: Vec<&str> = BUNDLED.iter().map(|(n, _)| *n).collect();
            Err(Error::Usage(format!(
                "machine `{name}` not found: no such file, and not a bundled machine ({})",
                names.join(", ")
            )))
        }
    }

    /// The bundled machine `name` (`afm-r1000`, `afm-r1000.yaml`,
    /// `machines/afm-r1000.yaml`).
    pub fn bundled(name: &str) -> Option<MachineFile> {
        let bare = name.strip_prefix("machines/").unwrap_or(name);
        let bare = bare
            .strip_suffix(".yaml")
            .or_else(|| bare.strip_suffix(".yml"))
            .unwrap_or(bare);
        BUNDLED
            .iter()
            .find(|(n, _)| *n == bare)
            .map(|(n, text)| MachineFile {
                shown: format!("{n}.yaml (bundled)"),
                file_name: format!("{n}.yaml"),
                path: None,
                text: Cow::Borrowed(text),
            })
    }

    /// Parses and validates the machine.
    pub fn load(&self) -> Result<Machine> {
        Machine::from_yaml_str(&self.text, &self.shown)
    }

    /// The validated machine and the file's `status`, from one reading of
    /// the text.
    pub fn read(&self) -> Result<(Machine, Status)> {
        let src = yaml::Source::read(&self.text, &self.shown)?;
        Ok((Machine::from_source(&src)?, Status::from_source(&src)?))
    }

    /// The file's `status` and `calibrations`.
    pub fn status(&self) -> Result<Status> {
        Status::from_yaml_str(&self.text, &self.shown)
    }

    /// SHA-256 of the file's bytes, lower-case hex (what `sha256sum`
    /// prints for the file).
    pub fn sha256(&self) -> String {
        status::sha256_hex(self.text.as_bytes())
    }

    /// Whether this is a bundled machine rather than a file on disk.
    pub fn is_bundled(&self) -> bool {
        self.path.is_none()
    }
}
