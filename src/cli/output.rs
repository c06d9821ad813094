//! Writing outputs: a temporary file beside the output, renamed into
//! place only once everything is written (nothing is left behind on an
//! error or an interrupt; two outputs of one run are put in place only
//! when both are written), standard output for `-`, devices and named
//! pipes written straight; default output names, and the refusal of an
//! output that would overwrite an input.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use super::usage;
use crate::error::{Error, Result};

/// The one rule naming a compensated program, for every language and
/// command (`compensate`, a RAPID program of several modules, `batch`):
/// `-o` when given; else, with an output folder, the program's path below
/// the folder input it was found in ([`in_folder`]); else
/// `<stem>.comp.<ext>` beside it ([`default_output`]). Standard input has
/// no name: it goes to standard output, and into no folder.
pub fn output_path(
    input: &Path,
    output: Option<&Path>,
    out_dir: Option<&Path>,
    roots: &[PathBuf],
) -> Result<PathBuf> {
    let stdin = input == Path::new("-");
    Ok(match (output, out_dir) {
        (Some(p), _) => p.to_path_buf(),
        (None, Some(_)) if stdin => {
            return Err(usage(
                "--out-dir needs a program file (standard input has no name): use -o",
            ));
        }
        (None, Some(dir)) => in_folder(dir, input, roots),
        (None, None) if stdin => PathBuf::from("-"),
        (None, None) => default_output(input),
    })
}

/// Where a program goes in the output folder `dir`: its path below the
/// first of the folder inputs `roots` that holds it, else its file name
/// ([`folder_name`]).
pub fn in_folder(dir: &Path, input: &Path, roots: &[PathBuf]) -> PathBuf {
    dir.join(folder_name(input, roots))
}

/// A program's name in an output folder: its path below the first of the
/// folders `roots` that holds it, else its file name (`program` for a path
/// without one).
pub fn folder_name<P: AsRef<Path>>(input: &Path, roots: &[P]) -> PathBuf {
    roots
        .iter()
        .map(AsRef::as_ref)
        .filter(|r| r.is_dir())
        .find_map(|r| input.strip_prefix(r).ok())
        .map(Path::to_path_buf)
        .or_else(|| input.file_name().map(PathBuf::from))
        .unwrap_or_else(|| PathBuf::from("program"))
}

/// Default output path: `<stem>.comp.<ext>` beside the input.
pub fn default_output(input: &Path) -> PathBuf {
    let stem = input
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_else(|| "program".into());
    let name = match input.extension() {
        Some(ext) => format!("{stem}.{COMPENSATED}.{}", ext.to_string_lossy()),
        None => format!("{stem}.{COMPENSATED}"),
    };
    input.with_file_name(name)
}

/// The word [`default_output`] puts between a program's stem and its
/// extension.
pub const COMPENSATED: &str = "comp";

/// Whether a file name is that of a compensated program, as
/// [`default_output`] names one (`part.comp.nc`): a batch over a folder
/// leaves such files out.
pub fn is_compensated_name(name: &str) -> bool {
    name.contains(&format!(".{COMPENSATED}."))
}

/// Refuses an output path that is one of the command's input files (stdout
/// `-` and stdin are never the same file). Every command that writes a file
/// calls this before writing.
pub fn refuse_overwrite<P: AsRef<Path>>(out: &Path, inputs: &[P]) -> Result<()> {
    if out == Path::new("-") {
        return Ok(());
    }
    for input in inputs.iter().map(AsRef::as_ref) {
        if input != Path::new("-") && (out == input || same_file(input, out)) {
            return Err(usage(format!(
                "{}: the output would overwrite the input",
                out.display()
            )));
        }
    }
    Ok(())
}

/// Whether the paths `a` and `b` name the same file: the same device and
/// inode when both exist (symbolic and hard links included), else the same
/// path once the folders are resolved (for a file not made yet: `./x`,
/// `d/../x` and an absolute spelling are one file).
pub(super) fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return x.dev() == y.dev() && x.ino() == y.ino();
        }
    }
    match (resolved(a), resolved(b)) {
        (Some(x), Some(y)) => x == y,
        _ => false,
    }
}

/// `path` with its links, `.` and `..` resolved, also when the file itself
/// does not exist yet (its folder is resolved and its name joined).
fn resolved(path: &Path) -> Option<PathBuf> {
    if let Ok(p) = path.canonicalize() {
        return Some(p);
    }
    let name = path.file_name()?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    Some(dir.canonicalize().ok()?.join(name))
}

/// Writes through a temporary file in the target directory and renames it
/// into place only when `f` succeeds; on failure nothing is left behind.
///
/// An output that already exists and is not an ordinary file (`/dev/null`,
/// `/dev/stdout`, a named pipe) is written to directly: renaming over it
/// would replace the device or pipe with a file. A symbolic link is followed,
/// so the file it points at is replaced and the link stays.
pub fn write_atomically<T>(path: &Path, f: impl FnOnce(&mut dyn Write) -> Result<T>) -> Result<T> {
    let mut out = Staged::file(path)?;
    let value = f(out.writer())?;
    out.finish()?.commit()?;
    Ok(value)
}

/// An output being written ([`write_atomically`]'s parts, for runs that
/// write two outputs and put neither in place unless both are written): a
/// temporary file beside it, renamed into place by [`Pending::commit`], or
/// a special file or standard output written straight.
pub(super) struct Staged {
    shown: PathBuf,
    sink: Sink,
}

enum Sink {
    /// A temporary file to be renamed to the path (removed on an
    /// interrupt while the guard lives).
    Temp(
        BufWriter<std::fs::File>,
        tempfile::TempPath,
        PathBuf,
        super::interrupt::Guard,
    ),
    /// A device or named pipe, written straight.
    Through(BufWriter<std::fs::File>),
    /// Standard output.
    Stdout(BufWriter<std::io::Stdout>),
}

/// A written output waiting to be put in place.
pub(super) struct Pending(
    Option<(
        tempfile::TempPath,
        PathBuf,
        PathBuf,
        super::interrupt::Guard,
    )>,
);

impl Staged {
    /// The output `path`, or standard output for `-`.
    pub(super) fn open(path: &Path) -> Result<Self> {
        if path == Path::new("-") {
            return Ok(Staged {
                shown: PathBuf::from("stdout"),
                sink: Sink::Stdout(BufWriter::new(std::io::stdout())),
            });
        }
        Staged::file(path)
    }

    /// The output file `path` (see [`write_atomically`]).
    fn file(path: &Path) -> Result<Self> {
        let is_link = std::fs::symlink_metadata(path)
            .map(|m| m.file_type().is_symlink())
            .unwrap_or(false);
        let target = match std::fs::metadata(path) {
            Ok(m) if !m.is_file() && !m.is_dir() => {
                let file = std::fs::OpenOptions::new()
                    .write(true)
                    .open(path)
                    .map_err(|e| Error::io(path, e))?;
                return Ok(Staged {
                    shown: path.to_path_buf(),
                    sink: Sink::Through(BufWriter::with_capacity(1 << 16, file)),
                });
            }
            Ok(m) if m.is_file() && is_link => {
                path.canonicalize().map_err(|e| Error::io(path, e))?
            }
            _ => path.to_path_buf(),
        };
        let dir = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        // The temporary file's random name means nothing to the user: name
        // the output and its folder only.
        let (tmp_path, file, guard) = super::interrupt::create_temp(&dir).map_err(|e| {
            Error::io(
                path,
                std::io::Error::new(
                    e.kind(),
                    format!("cannot create a file in {}: {}", dir.display(), e.kind()),
                ),
            )
        })?;
        Ok(Staged {
            shown: path.to_path_buf(),
            sink: Sink::Temp(
                BufWriter::with_capacity(1 << 20, file),
                tmp_path,
                target,
                guard,
            ),
        })
    }

    /// Where the output goes.
    pub(super) fn writer(&mut self) -> &mut dyn Write {
        match &mut self.sink {
            Sink::Temp(w, ..) | Sink::Through(w) => w,
            Sink::Stdout(w) => w,
        }
    }

    /// Flushes the output (and syncs a temporary file): what is left is to
    /// put it in place.
    pub(super) fn finish(self) -> Result<Pending> {
        let shown = self.shown;
        match self.sink {
            Sink::Through(mut w) => w.flush().map_err(|e| Error::io(&shown, e))?,
            Sink::Stdout(mut w) => w.flush().map_err(|e| Error::io(&shown, e))?,
            Sink::Temp(w, tmp_path, target, guard) => {
                let file = w
                    .into_inner()
                    .map_err(|e| Error::io(&shown, e.into_error()))?;
                file.sync_all().map_err(|e| Error::io(&shown, e))?;
                // Temporary files are private (0600); the result is an
                // ordinary file.
                #[cfg(unix)]
                {
                    use std::os::unix::fs::PermissionsExt;
                    file.set_permissions(std::fs::Permissions::from_mode(0o644))
                        .map_err(|e| Error::io(&shown, e))?;
                }
                return Ok(Pending(Some((tmp_path, target, shown, guard))));
            }
        }
        Ok(Pending(None))
    }
}

/// Finishes a program and its report, then puts both in place: neither
/// is, unless both are written.
pub(super) fn finish_both(out: Staged, report: Staged) -> Result<()> {
    let (report, out) = (report.finish()?, out.finish()?);
    out.commit()?;
    report.commit()
}

impl Pending {
    /// Puts the output in place (renames the temporary file).
    pub(super) fn commit(self) -> Result<()> {
        if let Some((tmp_path, target, shown, guard)) = self.0 {
            tmp_path
                .persist(&target)
                .map_err(|e| Error::io(&shown, e.error))?;
            drop(guard);
        }
        Ok(())
    }
}

/// Refuses a `--report` path that would replace the input or the output.
pub(super) fn check_report_path(
    report: Option<&Path>,
    inputs: &[PathBuf],
    output: &Path,
) -> Result<()> {
    let Some(report) = report else {
        return Ok(());
    };
    if report == Path::new("-") {
        return Err(usage("--report needs a file path (the program goes to -o)"));
    }
    let named = inputs.iter().map(|p| (p.as_path(), "input"));
    for (other, what) in named.chain([(output, "output")]) {
        if other != Path::new("-") && (report == other || same_file(report, other)) {
            return Err(usage(format!(
                "{}: the report would overwrite the {what}",
                report.display()
            )));
        }
    }
    Ok(())
}

/// Writes to `path` atomically, or to standard output for `-`.
pub(super) fn emit_to<T>(path: &Path, f: impl FnOnce(&mut dyn Write) -> Result<T>) -> Result<T> {
    let mut out = Staged::open(path)?;
    let value = f(out.writer())?;
    out.finish()?.commit()?;
    Ok(value)
}

/// Whether `err` is a write to a closed pipe (`postproc … | head`): the
/// reader has what it wanted, and the run ends quietly with exit 0.
pub fn is_broken_pipe(err: &Error) -> bool {
    matches!(err, Error::Io { cause, .. } if cause.kind() == std::io::ErrorKind::BrokenPipe)
}

/// Whether log lines are coloured: on a terminal, unless `NO_COLOR` is set
/// to anything but the empty string (no-color.org).
pub fn colour(terminal: bool, no_color: Option<&std::ffi::OsStr>) -> bool {
    terminal && no_color.is_none_or(|v| v.is_empty())
}

#[cfg(test)]
mod first_hour_tests {
    use super::*;

    #[test]
    fn one_naming_rule_for_beside_folder_and_standard_streams() {
        let dir = tempfile::tempdir().expect("a temporary folder");
        let root = dir.path().join("cell");
        std::fs::create_dir_all(root.join("sub")).expect("folders");
        let module = root.join("sub").join("Main.mod");
        let roots = [root.clone()];
        let out = Path::new("out");
        let named = |input: &Path, o: Option<&Path>, d: Option<&Path>, r: &[PathBuf]| {
            output_path(input, o, d, r).expect("a name")
        };
        assert_eq!(
            named(&module, None, None, &roots),
            root.join("sub").join("Main.comp.mod")
        );
        assert_eq!(
            named(&module, None, Some(out), &roots),
            out.join("sub").join("Main.mod")
        );
        assert_eq!(named(&module, None, Some(out), &[]), out.join("Main.mod"));
        assert_eq!(
            named(&module, Some(Path::new("x.mod")), Some(out), &roots),
            PathBuf::from("x.mod")
        );
        assert_eq!(named(Path::new("-"), None, None, &[]), PathBuf::from("-"));
        assert!(output_path(Path::new("-"), None, Some(out), &[]).is_err());
        assert_eq!(
            default_output(Path::new("PART")),
            PathBuf::from("PART.comp")
        );
        let beside = default_output(Path::new("d/p.nc"));
        let name = beside.file_name().and_then(|n| n.to_str()).expect("a name");
        assert_eq!(name, "p.comp.nc");
        assert!(is_compensated_name(name));
        assert!(!is_compensated_name("compass.nc"));
    }

    #[test]
    fn no_color_turns_colours_off_unless_empty() {
        use std::ffi::OsStr;
        assert!(colour(true, None));
        assert!(!colour(true, Some(OsStr::new("1"))));
        assert!(colour(true, Some(OsStr::new(""))));
        assert!(!colour(false, None));
    }

    #[test]
    fn a_closed_pipe_is_told_apart_from_other_write_errors() {
        let pipe = Error::io(
            "stdout",
            std::io::Error::from(std::io::ErrorKind::BrokenPipe),
        );
        assert!(is_broken_pipe(&pipe));
        let full = Error::io(
            "out.nc",
            std::io::Error::from(std::io::ErrorKind::StorageFull),
        );
        assert!(!is_broken_pipe(&full));
        assert!(!is_broken_pipe(&Error::Usage("x".into())));
    }
}
