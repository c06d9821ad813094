//! A RAPID program: the modules of one task, loaded together so that names
//! resolve across them as the controller resolves them.
//!
//! A program is given as module files, a folder (the task folder of a
//! controller backup, whose `PROGMOD` and `SYSMOD` sub-folders hold the
//! program and system modules: every `.mod`, `.modx`, `.sys` and `.prg`
//! below it) or a `.pgf` program file (XML whose `<Module>` elements name
//! the module files, relative to the `.pgf`). A module sees its own
//! declarations first, then the global ones of the other modules (not
//! those declared `LOCAL`; `TASK PERS` data is global within the task).
//! Data that a routine of another module writes is data written at run
//! time for the moves of a module.

use std::path::{Path, PathBuf};

use super::flow::Flow;
use super::flow::calls::Procedures;
use super::{Module, Scope, parse_module, parse_module_at};
use crate::error::{Error, Located, Result};
use crate::program::charset::Charset;

/// One module of a program: its file, text and syntax tree.
#[derive(Debug)]
pub struct Member {
    /// The file.
    pub path: PathBuf,
    /// The file name in messages.
    pub name: String,
    /// The text (decoded: UTF-8, or ISO-8859-1 when not valid UTF-8).
    pub text: String,
    /// The character set to write it back in.
    pub charset: Charset,
    /// The parsed module.
    pub module: Module,
}

/// The module files of the program that `inputs` name (module files,
/// folders searched recursively, `.pgf` program files), in order, each
/// once. Files named `*.comp.*` (compensated outputs) are passed over in a
/// folder.
pub fn module_files(inputs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut out: Vec<PathBuf> = Vec::new();
    for input in inputs {
        let found = if input.is_dir() {
            let mut v = Vec::new();
            walk(input, &mut v)?;
            v.sort();
            v
        } else if is_pgf(input) {
            pgf_modules(input)?
        } else {
            vec![input.clone()]
        };
        for f in found {
            if !out.contains(&f) {
                out.push(f);
            }
        }
    }
    if out.is_empty() {
        return Err(Error::Usage("no RAPID module in the program given".into()));
    }
    Ok(out)
}

/// True when `path` is a `.pgf` program file.
pub fn is_pgf(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("pgf"))
}

/// True when `inputs` name a program of several modules rather than one
/// module: more than one input, a folder or a `.pgf` file.
pub fn is_program(inputs: &[PathBuf]) -> bool {
    inputs.len() > 1 || inputs.iter().any(|p| p.is_dir() || is_pgf(p))
}

fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    for e in entries {
        let path = e.map_err(|e| Error::io(dir, e))?.path();
        if path.is_dir() {
            walk(&path, out)?;
        } else if super::super::language::rapid_extension(&path) && !is_output(&path) {
            out.push(path);
        }
    }
    Ok(())
}

/// True for a compensated output (`Main.comp.mod`).
fn is_output(path: &Path) -> bool {
    path.file_stem()
        .is_some_and(|s| s.to_string_lossy().to_ascii_lowercase().ends_with(".comp"))
}

/// The module files a `.pgf` program file lists: the text of each
/// `<Module>` element, relative to the `.pgf`'s folder (`\` read as `/`).
fn pgf_modules(pgf: &Path) -> Result<Vec<PathBuf>> {
    let bytes = crate::limits::read_file_bounded(pgf, 1 << 20)?;
    let (text, _) = crate::program::charset::decode(bytes);
    let dir = pgf.parent().unwrap_or(Path::new(""));
    let mut out = Vec::new();
    let lower = text.to_ascii_lowercase();
    let mut from = 0;
    while let Some(k) = lower.get(from..).and_then(|t| t.find("<module>")) {
        let start = from + k + "<module>".len();
        let Some(end) = lower.get(start..).and_then(|t| t.find("</module>")) else {
            break;
        };
        let name = text.get(start..start + end).unwrap_or("").trim();
        from = start + end;
        if !name.is_empty() {
            out.push(dir.join(name.replace('\\', "/")));
        }
    }
    if out.is_empty() {
        return Err(Error::Input(Located::whole_file(
            pgf.display().to_string(),
            "a program file lists no <Module>",
        )));
    }
    Ok(out)
}

/// Reads and parses the modules at `paths`.
pub fn load(paths: &[PathBuf]) -> Result<Vec<Member>> {
    let mut out = Vec::with_capacity(paths.len());
    for path in paths {
        let bytes = crate::limits::read_file_bounded(path, u64::MAX)?;
        let (text, charset) = crate::program::charset::decode(bytes);
        let name = path.display().to_string();
        let module = parse_module(&text, &name)
            .map_err(|e| crate::program::charset::file_columns(Error::Input(e), &text, charset))?;
        out.push(Member {
            path: path.clone(),
            name,
            text,
            charset,
            module,
        });
    }
    for (i, m) in out.iter().enumerate() {
        if let Some(other) = out
            .iter()
            .take(i)
            .find(|o| o.module.name.eq_ignore_ascii_case(&m.module.name))
        {
            return Err(Error::Input(Located::whole_file(
                m.name.clone(),
                format!(
                    "module {} is also in {}: a program holds each module once",
                    m.module.name, other.name
                ),
            )));
        }
    }
    Ok(out)
}

/// Module `i` of `members` with the declarations it sees in the other
/// modules, for its resolution: the text to resolve against (its own text
/// followed by a scope module holding those declarations as written), and
/// the module whose declarations are its own ones followed by those. The
/// spans of the own part are those of the module's text.
pub fn scoped(members: &[Member], i: usize) -> Result<(String, Module, Vec<Borrowed>)> {
    let own = members
        .get(i)
        .ok_or_else(|| Error::Internal("module index".into()))?;
    let mut tail = String::from("\nMODULE PostprocScope\n");
    let mut seen: Vec<&str> = Vec::new();
    let mut borrowed = Vec::new();
    for (j, m) in members.iter().enumerate() {
        if j == i {
            continue;
        }
        for d in &m.module.decls {
            if d.scope == Scope::Local
                || own.module.decl(&d.name).is_some()
                || seen.iter().any(|s| s.eq_ignore_ascii_case(&d.name))
            {
                continue;
            }
            seen.push(&d.name);
            borrowed.push(Borrowed {
                at: own.text.len() + tail.len(),
                member: j,
                span: d.span.clone(),
            });
            tail.push_str(m.text.get(d.span.clone()).unwrap_or(""));
            tail.push('\n');
        }
    }
    tail.push_str("ENDMODULE\n");
    let text = format!("{}{tail}", own.text);
    let scope = parse_module_at(&text, &own.name, own.text.len())?;
    let mut module = own.module.clone();
    module.decls.extend(scope.decls);
    Ok((text, module, borrowed))
}

/// A declaration of another module in the text [`scoped`] gives: where it
/// is there, and where it is in its own module.
#[derive(Debug, Clone)]
pub struct Borrowed {
    /// Its first byte in the scoped text.
    pub at: usize,
    /// The module it belongs to.
    pub member: usize,
    /// Its span in that module's text.
    pub span: super::Span,
}

/// An error located in the text [`scoped`] gave for module `i`, located in
/// the module it belongs to: one in a declaration of another module points
/// into that module's file.
pub fn relocate(
    e: Error,
    members: &[Member],
    i: usize,
    text: &str,
    borrowed: &[Borrowed],
) -> Error {
    let own_len = members.get(i).map_or(0, |m| m.text.len());
    let (Error::Input(loc) | Error::Unachievable(loc)) = &e else {
        return e;
    };
    // The byte offset of the location in the scoped text.
    let line_start = text
        .match_indices('\n')
        .nth(loc.line.saturating_sub(2))
        .map_or(0, |(k, _)| k + 1);
    let at = if loc.line <= 1 { 0 } else { line_start } + loc.column.saturating_sub(1);
    if at < own_len {
        return e;
    }
    let Some(b) = borrowed.iter().rev().find(|b| b.at <= at) else {
        return e;
    };
    let Some(m) = members.get(b.member) else {
        return e;
    };
    let there = (b.span.start + (at - b.at)).min(m.text.len());
    let (line, column) = super::resolve::line_col(&m.text, there);
    let moved = Located::new(m.name.clone(), line, column, loc.message.clone());
    match e {
        Error::Input(_) => Error::Input(moved),
        _ => Error::Unachievable(moved),
    }
}

/// The data names (lower case) that routines of the modules other than
/// `i` write.
pub fn written_elsewhere(members: &[Member], i: usize) -> Vec<String> {
    let mut out = Vec::new();
    for (j, m) in members.iter().enumerate() {
        if j != i {
            let procedures = procedures_elsewhere(members, j);
            out.extend(Flow::of_program(&m.module, &m.text, &procedures).written_names());
        }
    }
    out.sort_unstable();
    out.dedup();
    out
}

/// The procedures the modules other than `i` declare for it (not those
/// declared `LOCAL`), with their parameters.
pub fn procedures_elsewhere(members: &[Member], i: usize) -> Procedures {
    let mut out = Procedures::default();
    for (j, m) in members.iter().enumerate() {
        if j != i {
            out.extend(&Procedures::of_module(&m.module, &m.text, false));
        }
    }
    out
}
