//! ABB RAPID front end (syntax only).
//!
//! Parses one RAPID module (`MODULE … ENDMODULE`, optionally preceded by a
//! `%%% … %%%` header) into a syntax tree that keeps byte spans into the
//! source, so that [`crate::emit::rapid`] can rewrite exactly the numbers of a
//! robtarget and leave every other byte untouched.
//!
//! What is understood: data declarations (robtarget, jointtarget, tooldata,
//! wobjdata, speeddata, zonedata, num, bool, arrays of them), routines
//! (`PROC`, `FUNC`, `TRAP`) and the motion instructions of
//! [`instructions::MOTION_INSTRUCTIONS`] (`MoveL`, `MoveJ`, `MoveC`,
//! `MoveAbsJ`, `MoveLDO`, `TriggL`, `SearchL`, `ArcL`, …) with their
//! targets (named, array element, inline literal, `Offs`, `RelTool`). Every other statement is kept as an opaque
//! statement with its span. Record types (`RECORD … ENDRECORD`) are kept
//! with their fields, array sizes with their constant expressions, and a
//! routine that holds an editor placeholder (`<SMT>`, `<EXP>`, …) is
//! marked as unfinished. The accepted subset is documented in
//! `grammar/rapid.md`. Keywords are case-insensitive, as in RAPID.

pub mod directives;
pub mod flow;
pub mod instructions;
mod parser;
pub mod program;
pub mod resolve;
mod typed;
pub mod windows;

use std::ops::Range;

use crate::error::Located;

/// A byte range into the parsed source text.
pub type Span = Range<usize>;

/// A numeric literal: its value and the byte span of its text (sign included).
#[derive(Debug, Clone, PartialEq)]
pub struct Number {
    /// The value of the literal.
    pub value: f64,
    /// Where its text is in the source (`&src[span]` is e.g. `-1.5e-3`, or
    /// the name of the module's `CONST num` it was written as).
    pub span: Span,
}

/// Value of RAPID's "unused external axis" marker (`9E9`, `9E+09`).
pub const UNUSED_AXIS: f64 = 9e9;

impl Number {
    /// True when this is the `9E9` marker of an unused external axis.
    pub fn is_unused_axis(&self) -> bool {
        self.value >= UNUSED_AXIS * 0.999_999
    }
}

/// A `robtarget`: `[[x,y,z],[q1,q2,q3,q4],[cf1,cf4,cf6,cfx],[ea,eb,ec,ed,ee,ef]]`.
#[derive(Debug, Clone, PartialEq)]
pub struct RobTarget {
    /// Span of the whole literal, brackets included.
    pub span: Span,
    /// Position x, y, z in mm.
    pub trans: [Number; 3],
    /// Orientation quaternion q1 (scalar part), q2, q3, q4.
    pub rot: [Number; 4],
    /// Axis configuration cf1, cf4, cf6, cfx.
    pub robconf: [Number; 4],
    /// External axes a..f (`9E9` when unused).
    pub extax: [Number; 6],
}

/// A `jointtarget`: `[[rax_1..rax_6],[eax_a..eax_f]]` (degrees or mm).
#[derive(Debug, Clone, PartialEq)]
pub struct JointTarget {
    /// Span of the whole literal.
    pub span: Span,
    /// Robot axes 1..6.
    pub robax: [Number; 6],
    /// External axes a..f.
    pub extax: [Number; 6],
}

/// A `pose`: `[[x,y,z],[q1,q2,q3,q4]]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Pose {
    /// Span of the whole literal.
    pub span: Span,
    /// Translation in mm.
    pub trans: [Number; 3],
    /// Orientation quaternion, q1 the scalar part.
    pub rot: [Number; 4],
}

/// A `tooldata`: `[robhold, [[x,y,z],[q]], [mass, [cx,cy,cz], [aom q], ix, iy, iz]]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ToolData {
    /// Span of the whole literal.
    pub span: Span,
    /// TRUE when the robot holds the tool.
    pub robhold: bool,
    /// Tool frame (TCP) relative to the wrist flange.
    pub tframe: Pose,
    /// Mass in kg.
    pub mass: Number,
    /// Centre of gravity in mm (tool frame of the flange).
    pub cog: [Number; 3],
    /// Orientation of the principal axes of inertia.
    pub aom: [Number; 4],
    /// Moments of inertia ix, iy, iz in kg·m².
    pub inertia: [Number; 3],
}

/// A `wobjdata`: `[robhold, ufprog, "ufmec", uframe, oframe]`.
#[derive(Debug, Clone, PartialEq)]
pub struct WobjData {
    /// Span of the whole literal.
    pub span: Span,
    /// TRUE when the robot holds the work object.
    pub robhold: bool,
    /// TRUE for a fixed user frame.
    pub ufprog: bool,
    /// Mechanical unit moving the user frame (string contents, quotes removed).
    pub ufmec: String,
    /// User frame.
    pub uframe: Pose,
    /// Object frame (relative to the user frame).
    pub oframe: Pose,
}

/// A `speeddata`: `[v_tcp, v_ori, v_leax, v_reax]`.
#[derive(Debug, Clone, PartialEq)]
pub struct SpeedData {
    /// Span of the whole literal.
    pub span: Span,
    /// TCP speed (mm/s), reorientation (deg/s), linear and rotating external axes.
    pub values: [Number; 4],
}

/// A `zonedata`: `[finep, pzone_tcp, pzone_ori, pzone_eax, zone_ori, zone_leax, zone_reax]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ZoneData {
    /// Span of the whole literal.
    pub span: Span,
    /// TRUE for a stop point.
    pub finep: bool,
    /// The six zone sizes.
    pub values: [Number; 6],
}

/// The initial value of a declaration.
#[derive(Debug, Clone, PartialEq)]
pub enum DataValue {
    /// A robtarget literal.
    RobTarget(RobTarget),
    /// A jointtarget literal.
    JointTarget(JointTarget),
    /// A tooldata literal.
    ToolData(ToolData),
    /// A wobjdata literal.
    WobjData(WobjData),
    /// A speeddata literal.
    SpeedData(SpeedData),
    /// A zonedata literal.
    ZoneData(ZoneData),
    /// A num literal.
    Num(Number),
    /// A bool literal (`TRUE` / `FALSE`).
    Bool {
        /// The value.
        value: bool,
        /// Span of the keyword.
        span: Span,
    },
    /// An array value `[v1, v2, …]` of a declaration with `{n}`.
    Array {
        /// Span of the whole aggregate.
        span: Span,
        /// The elements, in order.
        items: Vec<DataValue>,
    },
    /// Anything else (another data type, an expression, a name): passed through.
    Other {
        /// Span of the value text.
        span: Span,
    },
}

impl DataValue {
    /// Span of the value text.
    pub fn span(&self) -> Span {
        match self {
            DataValue::RobTarget(v) => v.span.clone(),
            DataValue::JointTarget(v) => v.span.clone(),
            DataValue::ToolData(v) => v.span.clone(),
            DataValue::WobjData(v) => v.span.clone(),
            DataValue::SpeedData(v) => v.span.clone(),
            DataValue::ZoneData(v) => v.span.clone(),
            DataValue::Num(v) => v.span.clone(),
            DataValue::Bool { span, .. }
            | DataValue::Array { span, .. }
            | DataValue::Other { span } => span.clone(),
        }
    }
}

/// The data types the parser understands; every other type is `Other`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DataType {
    /// `robtarget`.
    RobTarget,
    /// `jointtarget`.
    JointTarget,
    /// `tooldata`.
    ToolData,
    /// `wobjdata`.
    WobjData,
    /// `speeddata`.
    SpeedData,
    /// `zonedata`.
    ZoneData,
    /// `num`.
    Num,
    /// `bool`.
    Bool,
    /// Any other type name, as written.
    Other(String),
}

impl DataType {
    /// Classifies a type name (case-insensitive).
    pub fn from_name(name: &str) -> DataType {
        match name.to_ascii_lowercase().as_str() {
            "robtarget" => DataType::RobTarget,
            "jointtarget" => DataType::JointTarget,
            "tooldata" => DataType::ToolData,
            "wobjdata" => DataType::WobjData,
            "speeddata" => DataType::SpeedData,
            "zonedata" => DataType::ZoneData,
            "num" => DataType::Num,
            "bool" => DataType::Bool,
            _ => DataType::Other(name.to_string()),
        }
    }
}

/// Scope prefix of a declaration or routine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scope {
    /// No prefix: visible in the whole task.
    Global,
    /// `LOCAL`.
    Local,
    /// `TASK`.
    Task,
}

/// Storage class of a declaration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Storage {
    /// `CONST`.
    Const,
    /// `PERS`.
    Pers,
    /// `VAR`.
    Var,
}

/// `[LOCAL|TASK] CONST|PERS|VAR type name[{n}] [:= value];`
#[derive(Debug, Clone, PartialEq)]
pub struct Decl {
    /// Scope prefix.
    pub scope: Scope,
    /// Storage class.
    pub storage: Storage,
    /// Classified type.
    pub data_type: DataType,
    /// The type name as written.
    pub type_name: String,
    /// The data name as written.
    pub name: String,
    /// Span of the data name.
    pub name_span: Span,
    /// Array dimensions (`{12}`, `{MAX_BUFFER}`, `{N+1, 3}`); empty for a
    /// scalar.
    pub dims: Vec<Dim>,
    /// The initial value, if any.
    pub value: Option<DataValue>,
    /// From the first keyword to the `;` included.
    pub span: Span,
    /// 1-based line of the first keyword.
    pub line: usize,
}

/// One array dimension of a declaration: an integer literal or a constant
/// expression (`MAX_BUFFER`, `N+1`).
#[derive(Debug, Clone, PartialEq)]
pub struct Dim {
    /// Span of its text, trimmed.
    pub span: Span,
    /// Its value: the literal, or the expression evaluated with the
    /// module's `CONST num` declarations before it (integers, `+`, `-`,
    /// `*`, `DIV`, parentheses); `None` when it cannot be known from the
    /// module (a constant of another module, an editor placeholder).
    pub value: Option<usize>,
}

/// A field of a `RECORD`: `type name;`.
#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    /// Classified type.
    pub data_type: DataType,
    /// The type name as written.
    pub type_name: String,
    /// The field name as written.
    pub name: String,
    /// From the type name to the `;` included.
    pub span: Span,
}

/// A record type declaration `[LOCAL] RECORD name { type field; } ENDRECORD`,
/// kept as written (a data declaration of its type is an ordinary
/// declaration whose value is passed through).
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// Scope prefix.
    pub scope: Scope,
    /// The record type name as written.
    pub name: String,
    /// The fields, in order.
    pub fields: Vec<Field>,
    /// From the first keyword to `ENDRECORD` included.
    pub span: Span,
    /// 1-based line of the first keyword.
    pub line: usize,
}

impl Record {
    /// The field named `name` (case-insensitive) and its 0-based position.
    pub fn field(&self, name: &str) -> Option<(usize, &Field)> {
        self.fields
            .iter()
            .enumerate()
            .find(|(_, f)| f.name.eq_ignore_ascii_case(name))
    }
}

/// The editor placeholders of RAPID (the program editor writes them where
/// a part of the program is still to be filled in): type, data and routine
/// declarations, parameters, alternative parameters, array dimensions,
/// statements, data references, `ELSEIF` and `CASE` clauses, expressions,
/// arguments and identifiers.
pub const PLACEHOLDERS: [&str; 13] = [
    "<TDN>", "<DDN>", "<RDN>", "<PAR>", "<ALT>", "<DIM>", "<SMT>", "<VAR>", "<EIT>", "<CSE>",
    "<EXP>", "<ARG>", "<ID>",
];

/// The placeholder at the start of `text` ([`PLACEHOLDERS`], as written:
/// upper case), if any.
pub fn placeholder_at(text: &str) -> Option<&'static str> {
    if !text.starts_with('<') {
        return None;
    }
    PLACEHOLDERS.iter().copied().find(|p| text.starts_with(p))
}

/// Byte offset of the first editor placeholder in `text` that is code (not
/// in a `!` comment or a string literal), if any.
pub fn find_placeholder(text: &str) -> Option<usize> {
    for at in memchr::memchr_iter(b'<', text.as_bytes()) {
        if placeholder_at(text.get(at..).unwrap_or("")).is_some() {
            let line_start = text
                .get(..at)
                .and_then(|t| t.rfind('\n'))
                .map_or(0, |p| p + 1);
            let line = text.get(line_start..at).unwrap_or("");
            if is_code_end(line) {
                return Some(at);
            }
        }
    }
    None
}

/// True when the end of `line` (a line's text up to a position) is code:
/// outside a string literal and before any `!` comment.
fn is_code_end(line: &str) -> bool {
    scan_line(line) == (None, false)
}

/// One pass over `line` (or the start of one): the byte offset of the `!`
/// that starts a comment (outside string literals) and whether the text
/// ends inside a string literal (only without a comment).
fn scan_line(line: &str) -> (Option<usize>, bool) {
    let mut in_string = false;
    for (i, b) in line.bytes().enumerate() {
        match b {
            b'"' => in_string = !in_string,
            b'!' if !in_string => return (Some(i), false),
            _ => {}
        }
    }
    (None, in_string)
}

/// An argument passed as written: its trimmed text and span.
#[derive(Debug, Clone, PartialEq)]
pub struct Arg {
    /// The text (e.g. `v100`, `tool1`, `[500,500,5000,1000]`), shared
    /// between the arguments of a module that read the same.
    pub text: std::sync::Arc<str>,
    /// Where it is.
    pub span: Span,
}

/// An optional argument `\Name` or `\Name:=value`.
#[derive(Debug, Clone, PartialEq)]
pub struct OptArg {
    /// Its name without the backslash, as written (`WObj`).
    pub name: String,
    /// The value after `:=`, absent for a switch (`\Conc`).
    pub value: Option<Arg>,
    /// From the backslash to the end of the value.
    pub span: Span,
}

/// A scalar argument of `Offs`/`RelTool`: its text and, when it is a plain
/// numeric literal, its value.
#[derive(Debug, Clone, PartialEq)]
pub struct Scalar {
    /// The trimmed text.
    pub text: String,
    /// Where it is.
    pub span: Span,
    /// The value when the text is a numeric literal.
    pub value: Option<f64>,
}

/// An array index `{…}`.
#[derive(Debug, Clone, PartialEq)]
pub struct Index {
    /// The text between the braces, trimmed (`2`, `i`, `i+1`).
    pub text: String,
    /// Span of that text.
    pub span: Span,
    /// The value when it is an integer literal (1-based, as in RAPID).
    pub value: Option<usize>,
}

impl Index {
    /// The index of each dimension (`1, 2` of `grid{1, 2}` gives `1` and
    /// `2`): the text cut at its commas outside parentheses, brackets and
    /// strings, each part trimmed.
    pub fn parts(&self) -> Vec<&str> {
        let mut out = Vec::new();
        let (mut depth, mut quoted, mut from) = (0usize, false, 0);
        for (k, c) in self.text.char_indices() {
            match c {
                '"' => quoted = !quoted,
                '(' | '[' | '{' if !quoted => depth += 1,
                ')' | ']' | '}' if !quoted => depth = depth.saturating_sub(1),
                ',' if !quoted && depth == 0 => {
                    out.extend(self.text.get(from..k).map(str::trim));
                    from = k + 1;
                }
                _ => {}
            }
        }
        out.extend(self.text.get(from..).map(str::trim));
        out
    }

    /// The value of each dimension's index when every one is an integer
    /// literal (1-based).
    pub fn literals(&self) -> Option<Vec<usize>> {
        if let Some(v) = self.value {
            return Some(vec![v]);
        }
        self.parts()
            .into_iter()
            .map(|p| {
                if p.is_empty() || !p.bytes().all(|b| b.is_ascii_digit()) {
                    return None;
                }
                p.parse().ok()
            })
            .collect()
    }
}

/// The target expression of a move.
#[derive(Debug, Clone, PartialEq)]
pub enum Target {
    /// A data name, optionally indexed: `p10`, `holes{3}`.
    Named {
        /// The name as written.
        name: String,
        /// The index, for an array element.
        index: Option<Index>,
        /// The whole expression.
        span: Span,
    },
    /// An inline robtarget literal.
    Inline(RobTarget),
    /// An inline jointtarget literal (MoveAbsJ).
    InlineJoint(JointTarget),
    /// `Offs(base, dx, dy, dz)`: displacement in the work-object frame.
    Offs {
        /// The displaced target.
        base: Box<Target>,
        /// dx, dy, dz in mm.
        offsets: [Scalar; 3],
        /// The whole call.
        span: Span,
    },
    /// `RelTool(base, dx, dy, dz [\Rx:=a] [\Ry:=b] [\Rz:=c])`: displacement
    /// and rotation (degrees) in the tool frame.
    RelTool {
        /// The displaced target.
        base: Box<Target>,
        /// dx, dy, dz in mm.
        offsets: [Scalar; 3],
        /// Rotation about the tool x axis.
        rx: Option<Scalar>,
        /// Rotation about the tool y axis.
        ry: Option<Scalar>,
        /// Rotation about the tool z axis.
        rz: Option<Scalar>,
        /// The whole call.
        span: Span,
    },
    /// Any other expression (a function call such as `CRobT()`): passed through.
    Other {
        /// The trimmed text.
        text: String,
        /// Where it is.
        span: Span,
    },
}

impl Target {
    /// Span of the whole target expression.
    pub fn span(&self) -> Span {
        match self {
            Target::Inline(r) => r.span.clone(),
            Target::InlineJoint(j) => j.span.clone(),
            Target::Named { span, .. }
            | Target::Offs { span, .. }
            | Target::RelTool { span, .. }
            | Target::Other { span, .. } => span.clone(),
        }
    }
}

/// How a motion instruction moves the TCP (the instruction itself, with
/// its own argument order, is named by [`Move::name`]; see
/// [`instructions::MOTION_INSTRUCTIONS`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MoveKind {
    /// `MoveL`: linear.
    MoveL,
    /// `MoveJ`: joint interpolated to a robtarget.
    MoveJ,
    /// `MoveC`: circular through a via point.
    MoveC,
    /// `MoveAbsJ`: joint interpolated to a jointtarget.
    MoveAbsJ,
}

impl MoveKind {
    /// The instruction name in its canonical spelling.
    pub fn name(self) -> &'static str {
        match self {
            MoveKind::MoveL => "MoveL",
            MoveKind::MoveJ => "MoveJ",
            MoveKind::MoveC => "MoveC",
            MoveKind::MoveAbsJ => "MoveAbsJ",
        }
    }
}

/// A motion instruction with its arguments.
#[derive(Debug, Clone, PartialEq)]
pub struct Move {
    /// The instruction's name in its canonical spelling (`MoveL`,
    /// `MoveLDO`, `ArcL`, …), for messages, reports and annotations.
    pub name: &'static str,
    /// How it moves: what prediction and compensation use.
    pub kind: MoveKind,
    /// The circle point of a circular move (boxed: only those have one,
    /// and a `Target` is as large as an inline robtarget).
    pub via: Option<Box<Target>>,
    /// The target (`ToPoint`, or `ToJointPos` for `MoveAbsJ`).
    pub target: Target,
    /// Speed argument (`v100`).
    pub speed: Arg,
    /// Zone argument (`z10`, `fine`); `None` for an instruction without
    /// one (`SearchL`, `SearchC`).
    pub zone: Option<Arg>,
    /// Tool argument.
    pub tool: Arg,
    /// Value of `\WObj:=`.
    pub wobj: Option<Arg>,
    /// Value of `\TLoad:=`.
    pub tload: Option<Arg>,
    /// True when `\Conc` is given.
    pub conc: bool,
    /// Every optional argument in source order (`\V`, `\Z`, `\ID`, …).
    pub optional: Vec<OptArg>,
    /// From the instruction name to the `;` included.
    pub span: Span,
    /// 1-based line of the instruction name.
    pub line: usize,
    /// When the move is the statement of a compact `IF cond stmt` (on the
    /// same line or the next): from `IF` to the end of the condition, kept
    /// as written. The move goes to its target whenever it runs.
    pub condition: Option<Span>,
}

impl Move {
    /// The optional argument `name` (case-insensitive), if given.
    pub fn opt(&self, name: &str) -> Option<&OptArg> {
        self.optional
            .iter()
            .find(|o| o.name.eq_ignore_ascii_case(name))
    }
}

/// An assignment `name := value;`, `name{index} := value;` or
/// `name.field := value;` (a component of the data).
#[derive(Debug, Clone, PartialEq)]
pub struct Assign {
    /// The assigned data name as written.
    pub name: String,
    /// The index, for an array element.
    pub index: Option<Index>,
    /// True when a component is assigned (`p.trans.z := 10;`), not the
    /// whole value.
    pub component: bool,
    /// The value, read as a target expression: a robtarget literal, a
    /// name, `Offs`/`RelTool`, or any other expression (`CRobT()`, `n + 1`,
    /// a number) as [`Target::Other`].
    pub value: Target,
    /// From the name to the `;` included.
    pub span: Span,
    /// 1-based line of the name.
    pub line: usize,
}

/// One statement of a routine body.
#[derive(Debug, Clone, PartialEq)]
pub enum Stmt {
    /// A motion instruction (boxed: it is much larger than the other variants).
    Move(Box<Move>),
    /// A routine-local data declaration (boxed, as `Move`).
    Decl(Box<Decl>),
    /// A control-flow line (`IF … THEN`, `ELSE`, `ENDIF`, `FOR … DO`,
    /// `ENDFOR`, `WHILE … DO`, `TEST …`, `CASE …:`, labels, `ERROR`). The
    /// bodies are not nested: the statements between stay in the flat list.
    Control {
        /// The leading keyword in upper case (`IF`, `ENDFOR`, or `LABEL`).
        keyword: String,
        /// The line's span.
        span: Span,
        /// 1-based line.
        line: usize,
    },
    /// An assignment (boxed, as `Move`).
    Assign(Box<Assign>),
    /// Any other statement, up to and including its `;`, passed through.
    Opaque {
        /// Its span.
        span: Span,
        /// 1-based line of its first byte.
        line: usize,
    },
}

impl Stmt {
    /// The statement's span.
    pub fn span(&self) -> Span {
        match self {
            Stmt::Move(m) => m.condition.as_ref().map_or(m.span.start, |c| c.start)..m.span.end,
            Stmt::Decl(d) => d.span.clone(),
            Stmt::Assign(a) => a.span.clone(),
            Stmt::Control { span, .. } | Stmt::Opaque { span, .. } => span.clone(),
        }
    }
}

/// `ConfL`/`ConfJ` with a switch: `(linear, off)` of a statement's text
/// (`ConfL \Off;`, `confj\on;`); `None` for any other statement or no
/// switch.
fn conf_switch(text: &str) -> Option<(bool, bool)> {
    let t = text.trim_start();
    let word = t.get(..5)?;
    let linear = if word.eq_ignore_ascii_case("ConfL") {
        true
    } else if word.eq_ignore_ascii_case("ConfJ") {
        false
    } else {
        return None;
    };
    let rest = t[5..].trim_start();
    let rest = rest.strip_prefix('\\')?.trim_start();
    let switch: String = rest
        .chars()
        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
        .collect();
    if switch.eq_ignore_ascii_case("Off") {
        Some((linear, true))
    } else if switch.eq_ignore_ascii_case("On") {
        Some((linear, false))
    } else {
        None
    }
}

/// Configuration monitoring at a point of a routine: whether `ConfL \Off`
/// or `ConfJ \Off` is in force (both on at the start of a routine).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ConfMonitoring {
    /// `ConfL \Off` in force (linear and circular moves).
    pub linear_off: bool,
    /// `ConfJ \Off` in force (joint moves).
    pub joint_off: bool,
}

/// Routine kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RoutineKind {
    /// `PROC … ENDPROC`.
    Proc,
    /// `FUNC type … ENDFUNC`.
    Func,
    /// `TRAP … ENDTRAP`.
    Trap,
}

/// A routine (`PROC`, `FUNC` or `TRAP`) and its flat list of statements.
#[derive(Debug, Clone, PartialEq)]
pub struct Proc {
    /// Routine kind.
    pub kind: RoutineKind,
    /// Scope prefix.
    pub scope: Scope,
    /// Routine name.
    pub name: String,
    /// Text between the parentheses (parameters), not parsed.
    pub params: Option<Span>,
    /// The statements, in order.
    pub body: Vec<Stmt>,
    /// From the first keyword to the end keyword included.
    pub span: Span,
    /// 1-based line of the routine keyword.
    pub line: usize,
    /// True when the routine holds an editor placeholder (`<SMT>`,
    /// `<EXP>`, … in its code): it is unfinished, and is left as written
    /// ([`Module::moves`] passes over it).
    pub placeholder: bool,
}

impl Proc {
    /// The motion instructions of the routine's body, in source order.
    pub fn moves(&self) -> impl Iterator<Item = &Move> {
        self.body.iter().filter_map(|s| match s {
            Stmt::Move(m) => Some(m.as_ref()),
            _ => None,
        })
    }
}

/// A parsed RAPID module.
#[derive(Debug, Clone, PartialEq)]
pub struct Module {
    /// Module name.
    pub name: String,
    /// From `MODULE` to `ENDMODULE` included.
    pub span: Span,
    /// The `%%% … %%%` header, if any.
    pub header: Option<Span>,
    /// Text between the parentheses after the name (`SYSMODULE, NOSTEPIN`).
    pub attributes: Option<Span>,
    /// Module-level declarations, in order.
    pub decls: Vec<Decl>,
    /// Record type declarations, in order.
    pub records: Vec<Record>,
    /// Editor placeholders standing for a module-level declaration
    /// (`<DDN>`, `<RDN>`, `<TDN>`), in order.
    pub placeholders: Vec<Span>,
    /// Routines, in order.
    pub procs: Vec<Proc>,
}

impl Module {
    /// The module-level declaration named `name` (case-insensitive, as RAPID).
    pub fn decl(&self, name: &str) -> Option<&Decl> {
        self.decls
            .iter()
            .find(|d| d.name.eq_ignore_ascii_case(name))
    }

    /// The routine named `name` (case-insensitive).
    pub fn proc(&self, name: &str) -> Option<&Proc> {
        self.procs
            .iter()
            .find(|p| p.name.eq_ignore_ascii_case(name))
    }

    /// The record type named `name` (case-insensitive).
    pub fn record(&self, name: &str) -> Option<&Record> {
        self.records
            .iter()
            .find(|r| r.name.eq_ignore_ascii_case(name))
    }

    /// Every motion instruction of every routine, in source order, except
    /// those of routines holding an editor placeholder ([`Proc::placeholder`]):
    /// an unfinished routine is left as written.
    pub fn moves(&self) -> impl Iterator<Item = &Move> {
        self.procs
            .iter()
            .filter(|p| !p.placeholder)
            .flat_map(Proc::moves)
    }

    /// Span starts (in source order) of the moves whose configuration
    /// monitoring is off: a `MoveL`/`MoveC`-kind move after `ConfL \Off`, a
    /// `MoveJ`-kind move after `ConfJ \Off`, until `\On` (`src` is the text
    /// this module was parsed from). The state follows the statements of a
    /// routine in source order and starts on (the controller's state at
    /// program start) in every routine. `MoveAbsJ` has no configuration.
    pub fn configuration_free_moves(&self, src: &str) -> Vec<usize> {
        self.configuration_free_moves_from(src, ConfMonitoring::default())
            .0
    }

    /// [`Module::configuration_free_moves`] with the first routine's state
    /// starting at `start` (a window of a routine continues the state the
    /// windows before it left); also gives the state at the end of the last
    /// routine.
    pub fn configuration_free_moves_from(
        &self,
        src: &str,
        start: ConfMonitoring,
    ) -> (Vec<usize>, ConfMonitoring) {
        let mut out = Vec::new();
        let mut state = start;
        for (i, p) in self.procs.iter().filter(|p| !p.placeholder).enumerate() {
            state = if i == 0 {
                start
            } else {
                ConfMonitoring::default()
            };
            for s in &p.body {
                match s {
                    Stmt::Opaque { span, .. } => {
                        match src.get(span.clone()).and_then(conf_switch) {
                            Some((true, off)) => state.linear_off = off,
                            Some((false, off)) => state.joint_off = off,
                            None => {}
                        }
                    }
                    Stmt::Move(m) => {
                        let off = match m.kind {
                            MoveKind::MoveL | MoveKind::MoveC => state.linear_off,
                            MoveKind::MoveJ => state.joint_off,
                            MoveKind::MoveAbsJ => false,
                        };
                        if off {
                            out.push(m.span.start);
                        }
                    }
                    _ => {}
                }
            }
        }
        (out, state)
    }

    /// The motion instructions of routines that hold an editor placeholder
    /// (`<SMT>`, …), in source order: such a routine is left as written.
    pub fn unfinished_moves(&self) -> impl Iterator<Item = &Move> {
        self.procs
            .iter()
            .filter(|p| p.placeholder)
            .flat_map(Proc::moves)
    }

    /// The opaque statements of `src` (the text this module was parsed
    /// from) that look like a motion instruction — a first word starting
    /// with one of [`MOTION_LIKE_PREFIXES`]: a name not in
    /// [`instructions::MOTION_INSTRUCTIONS`], or one of its
    /// [`instructions::MotionInstruction::other_forms`] entries written
    /// with other arguments — and name a robtarget declared in the module
    /// or in their routine (`PaintL p10, …`): they are passed through as
    /// written and not compensated. In source order.
    pub fn unknown_motions(&self, src: &str) -> Vec<UnknownMotion> {
        let module_targets: Vec<&str> = robtarget_names(self.decls.iter());
        let mut out = Vec::new();
        for p in &self.procs {
            let local_targets = robtarget_names(p.body.iter().filter_map(|s| match s {
                Stmt::Decl(d) => Some(d.as_ref()),
                _ => None,
            }));
            for s in &p.body {
                let Stmt::Opaque { span, line } = s else {
                    continue;
                };
                let Some(text) = src.get(span.clone()) else {
                    continue;
                };
                let Some(name) = motion_like_word(text) else {
                    continue;
                };
                let names_target = words(&text[name.len()..]).any(|w| {
                    module_targets
                        .iter()
                        .chain(&local_targets)
                        .any(|t| t.eq_ignore_ascii_case(w))
                });
                if names_target {
                    out.push(UnknownMotion {
                        name: name.to_string(),
                        line: *line,
                        column: column_of(src, span.start),
                    });
                }
            }
        }
        out
    }
}

/// First-word prefixes of the instructions that may move the TCP to a
/// robtarget (`Move…`, `Trigg…`, `Search…`, `Arc…`, `Spot…`, `Paint…`,
/// `Cap…`, `Disp…`), matched case-insensitively.
pub const MOTION_LIKE_PREFIXES: &[&str] = &[
    "Move", "Trigg", "Search", "Arc", "Spot", "Paint", "Cap", "Disp",
];

/// A statement that looks like a motion instruction to a declared
/// robtarget but is not a move of the table of motion instructions.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownMotion {
    /// Its first word as written (`PaintL`).
    pub name: String,
    /// 1-based line of its first byte.
    pub line: usize,
    /// 1-based byte column of its first byte.
    pub column: usize,
}

/// 1-based byte column of byte offset `at` of `src`.
pub fn column_of(src: &str, at: usize) -> usize {
    let before = src.get(..at).unwrap_or(src);
    before.len() - before.rfind('\n').map_or(0, |k| k + 1) + 1
}

/// The names of the robtarget declarations of `decls`.
fn robtarget_names<'a>(decls: impl Iterator<Item = &'a Decl>) -> Vec<&'a str> {
    decls
        .filter(|d| d.data_type == DataType::RobTarget)
        .map(|d| d.name.as_str())
        .collect()
}

/// The first word of `text` when it starts with a motion-like prefix and
/// is used as an instruction (not assigned: no `:=` right after it).
fn motion_like_word(text: &str) -> Option<&str> {
    let n = text
        .bytes()
        .take_while(|b| b.is_ascii_alphanumeric() || *b == b'_')
        .count();
    let word = text.get(..n)?;
    let prefixed = MOTION_LIKE_PREFIXES.iter().any(|p| {
        word.len() > p.len()
            && word
                .get(..p.len())
                .is_some_and(|h| h.eq_ignore_ascii_case(p))
    });
    let assigned = text.get(n..)?.trim_start().starts_with(":=");
    (prefixed && !assigned).then_some(word)
}

/// The identifiers of `text`, outside strings and `!` comments.
pub(crate) fn words(text: &str) -> impl Iterator<Item = &str> {
    let mut in_string = false;
    let mut in_comment = false;
    let mut start = None;
    let mut out = Vec::new();
    for (k, c) in text.char_indices() {
        let ident = c.is_ascii_alphanumeric() || c == '_';
        if let Some(s) = start
            && !ident
        {
            out.push(&text[s..k]);
            start = None;
        }
        if in_comment {
            in_comment = c != '\n';
        } else if in_string {
            in_string = c != '"';
        } else if c == '"' {
            in_string = true;
        } else if c == '!' {
            in_comment = true;
        } else if ident && start.is_none() {
            start = Some(k);
        }
    }
    if let Some(s) = start {
        out.push(&text[s..]);
    }
    out.into_iter()
}

/// Byte offset of the `!` that starts a RAPID comment on `line` (outside
/// string literals; strings do not span lines).
pub fn comment_start(line: &str) -> Option<usize> {
    scan_line(line).0
}

/// Parses a RAPID module from text. `file` is used in error messages only.
///
/// Errors read `file:line:column: what, found `text``; no input panics.
pub fn parse_module(src: &str, file: &str) -> Result<Module, Located> {
    lone_cr(src, file, 0)?;
    parser::Parser::new(src, file).parse()
}

/// Refuses a carriage return (CR) from byte `start` on that does not begin
/// a CR LF line end: lines end in LF or CR LF, and with CR alone a comment
/// would run on over the lines after it.
fn lone_cr(src: &str, file: &str, start: usize) -> Result<(), Located> {
    let bytes = src.as_bytes();
    let tail = bytes.get(start..).unwrap_or(b"");
    for p in memchr::memchr_iter(b'\r', tail).map(|p| p + start) {
        if bytes.get(p + 1) != Some(&b'\n') {
            let (line, column) = resolve::line_col(src, p);
            return Err(Located::new(
                file,
                line,
                column,
                "carriage return (CR) without a line feed: lines end in LF or CR LF (a file with CR-only line ends must be converted)".to_string(),
            ));
        }
    }
    Ok(())
}

/// Parses the RAPID module that starts at byte `start` of `src` (and ends
/// it), with spans into the whole of `src`.
pub fn parse_module_at(src: &str, file: &str, start: usize) -> Result<Module, Located> {
    lone_cr(src, file, start)?;
    parser::Parser::new(src, file).parse_from(start)
}

/// Parses a RAPID module from bytes, rejecting invalid UTF-8 with the line
/// and column of the first bad byte.
pub fn parse_module_bytes(src: &[u8], file: &str) -> Result<Module, Located> {
    parse_module(crate::error::utf8_text(src, file)?, file)
}
