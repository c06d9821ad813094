//! Checking a generic aggregate value against its RAPID data type and
//! building the typed literal (robtarget, jointtarget, tooldata, …).
//!
//! A wrong shape (e.g. a robtarget rotation with three numbers) is an error;
//! an element that is a name or an expression instead of a literal makes the
//! whole value pass through as [`DataValue::Other`].

use super::parser::{Parser, Val};
use super::{
    DataType, DataValue, Decl, Dim, JointTarget, Number, Pose, RobTarget, SpeedData, Storage,
    ToolData, WobjData, ZoneData,
};

type E<'a> = nom::Err<super::parser::PErr<'a>>;

/// Shape of a robtarget, for messages.
const ROBTARGET_SHAPE: &str = "robtarget must be [[x,y,z],[q1,q2,q3,q4],[cf1,cf4,cf6,cfx],[eax_a,eax_b,eax_c,eax_d,eax_e,eax_f]]";
const JOINTTARGET_SHAPE: &str = "jointtarget must be [[rax_1,…,rax_6],[eax_a,…,eax_f]]";
const POSE_SHAPE: &str = "pose must be [[x,y,z],[q1,q2,q3,q4]]";
const TOOLDATA_SHAPE: &str =
    "tooldata must be [robhold,[[x,y,z],[q1,q2,q3,q4]],[mass,[cx,cy,cz],[q1,q2,q3,q4],ix,iy,iz]]";
const WOBJDATA_SHAPE: &str =
    "wobjdata must be [robhold,ufprog,\"ufmec\",[[x,y,z],[q1,q2,q3,q4]],[[x,y,z],[q1,q2,q3,q4]]]";
const SPEEDDATA_SHAPE: &str = "speeddata must be [v_tcp,v_ori,v_leax,v_reax]";
const ZONEDATA_SHAPE: &str =
    "zonedata must be [finep,pzone_tcp,pzone_ori,pzone_eax,zone_ori,zone_leax,zone_reax]";

impl<'a> Parser<'a> {
    /// The typed value of a declaration of `data_type` with `dims`.
    pub(super) fn typed_value(
        &self,
        data_type: &DataType,
        dims: &[Dim],
        v: &Val,
    ) -> Result<DataValue, E<'a>> {
        if let Some((dim, inner)) = dims.split_first() {
            return match v {
                Val::List { span, items } => {
                    if let Some(n) = dim.value.filter(|&n| items.len() != n) {
                        return Err(self.err_found(
                            span.start,
                            &format!(
                                "array declared with {n} elements has {} in its value",
                                items.len()
                            ),
                        ));
                    }
                    let items = items
                        .iter()
                        .map(|item| self.typed_value(data_type, inner, item))
                        .collect::<Result<Vec<_>, _>>()?;
                    Ok(DataValue::Array {
                        span: span.clone(),
                        items,
                    })
                }
                other => Ok(DataValue::Other { span: other.span() }),
            };
        }
        let other = || DataValue::Other { span: v.span() };
        Ok(match data_type {
            DataType::RobTarget => self
                .rob_target_opt(v)?
                .map_or_else(other, DataValue::RobTarget),
            DataType::JointTarget => self
                .joint_target_opt(v)?
                .map_or_else(other, DataValue::JointTarget),
            DataType::ToolData => self.tool_data(v)?.map_or_else(other, DataValue::ToolData),
            DataType::WobjData => self.wobj_data(v)?.map_or_else(other, DataValue::WobjData),
            DataType::SpeedData => self.speed_data(v)?.map_or_else(other, DataValue::SpeedData),
            DataType::ZoneData => self.zone_data(v)?.map_or_else(other, DataValue::ZoneData),
            DataType::Num => match v {
                Val::Num(n) => DataValue::Num(n.clone()),
                Val::Word { .. } | Val::Expr { .. } => other(),
                _ => return Err(self.err_found(v.span().start, "a num value must be a number")),
            },
            DataType::Bool => match self.boolean(v, "a bool value must be TRUE or FALSE")? {
                Some(value) => DataValue::Bool {
                    value,
                    span: v.span(),
                },
                None => other(),
            },
            DataType::Other(_) => other(),
        })
    }

    /// An inline robtarget of a move: every element must be a literal.
    pub(super) fn rob_target(&self, v: &Val) -> Result<RobTarget, E<'a>> {
        self.rob_target_opt(v)?.ok_or_else(|| {
            self.err_found(
                v.span().start,
                "an inline robtarget must contain numeric literals only",
            )
        })
    }

    /// An inline jointtarget of a move: every element must be a literal.
    pub(super) fn joint_target(&self, v: &Val) -> Result<JointTarget, E<'a>> {
        self.joint_target_opt(v)?.ok_or_else(|| {
            self.err_found(
                v.span().start,
                "an inline jointtarget must contain numeric literals only",
            )
        })
    }

    fn rob_target_opt(&self, v: &Val) -> Result<Option<RobTarget>, E<'a>> {
        let Some(parts) = self.list(v, 4, ROBTARGET_SHAPE, "it")? else {
            return Ok(None);
        };
        let [t, r, c, x] = parts else {
            return Ok(None);
        };
        let trans = self.nums::<3>(t, ROBTARGET_SHAPE, "trans [x,y,z]")?;
        let rot = self.nums::<4>(r, ROBTARGET_SHAPE, "rot [q1,q2,q3,q4]")?;
        let robconf = self.nums::<4>(c, ROBTARGET_SHAPE, "robconf [cf1,cf4,cf6,cfx]")?;
        let extax = self.nums::<6>(x, ROBTARGET_SHAPE, "extax [eax_a,…,eax_f]")?;
        Ok(match (trans, rot, robconf, extax) {
            (Some(trans), Some(rot), Some(robconf), Some(extax)) => Some(RobTarget {
                span: v.span(),
                trans,
                rot,
                robconf,
                extax,
            }),
            _ => None,
        })
    }

    fn joint_target_opt(&self, v: &Val) -> Result<Option<JointTarget>, E<'a>> {
        let Some(parts) = self.list(v, 2, JOINTTARGET_SHAPE, "it")? else {
            return Ok(None);
        };
        let [r, x] = parts else {
            return Ok(None);
        };
        let robax = self.nums::<6>(r, JOINTTARGET_SHAPE, "robax")?;
        let extax = self.nums::<6>(x, JOINTTARGET_SHAPE, "extax")?;
        Ok(match (robax, extax) {
            (Some(robax), Some(extax)) => Some(JointTarget {
                span: v.span(),
                robax,
                extax,
            }),
            _ => None,
        })
    }

    fn pose(&self, v: &Val, shape: &str, what: &str) -> Result<Option<Pose>, E<'a>> {
        let Some(parts) = self.list(v, 2, shape, what)? else {
            return Ok(None);
        };
        let [t, r] = parts else {
            return Ok(None);
        };
        let trans = self.nums::<3>(t, POSE_SHAPE, "trans [x,y,z]")?;
        let rot = self.nums::<4>(r, POSE_SHAPE, "rot [q1,q2,q3,q4]")?;
        Ok(match (trans, rot) {
            (Some(trans), Some(rot)) => Some(Pose {
                span: v.span(),
                trans,
                rot,
            }),
            _ => None,
        })
    }

    fn tool_data(&self, v: &Val) -> Result<Option<ToolData>, E<'a>> {
        let s = TOOLDATA_SHAPE;
        let Some(parts) = self.list(v, 3, s, "it")? else {
            return Ok(None);
        };
        let [h, f, l] = parts else {
            return Ok(None);
        };
        let robhold = self.boolean(h, &format!("{s}: robhold must be TRUE or FALSE"))?;
        let tframe = self.pose(f, s, "tframe")?;
        let Some(load) = self.list(l, 6, s, "tload [mass,[cog],[aom],ix,iy,iz]")? else {
            return Ok(None);
        };
        let [m, c, a, ix, iy, iz] = load else {
            return Ok(None);
        };
        let mass = self.num(m, s)?;
        let cog = self.nums::<3>(c, s, "cog [cx,cy,cz]")?;
        let aom = self.nums::<4>(a, s, "aom [q1,q2,q3,q4]")?;
        let ix = self.num(ix, s)?;
        let iy = self.num(iy, s)?;
        let iz = self.num(iz, s)?;
        Ok(match (robhold, tframe, mass, cog, aom, ix, iy, iz) {
            (
                Some(robhold),
                Some(tframe),
                Some(mass),
                Some(cog),
                Some(aom),
                Some(ix),
                Some(iy),
                Some(iz),
            ) => Some(ToolData {
                span: v.span(),
                robhold,
                tframe,
                mass,
                cog,
                aom,
                inertia: [ix, iy, iz],
            }),
            _ => None,
        })
    }

    fn wobj_data(&self, v: &Val) -> Result<Option<WobjData>, E<'a>> {
        let s = WOBJDATA_SHAPE;
        let Some(parts) = self.list(v, 5, s, "it")? else {
            return Ok(None);
        };
        let [h, p, m, u, o] = parts else {
            return Ok(None);
        };
        let robhold = self.boolean(h, &format!("{s}: robhold must be TRUE or FALSE"))?;
        let ufprog = self.boolean(p, &format!("{s}: ufprog must be TRUE or FALSE"))?;
        let ufmec = match m {
            Val::Str { text, .. } => Some(text.clone()),
            Val::Word { .. } | Val::Expr { .. } => None,
            _ => {
                return Err(self.err_found(m.span().start, &format!("{s}: ufmec must be a string")));
            }
        };
        let uframe = self.pose(u, s, "uframe")?;
        let oframe = self.pose(o, s, "oframe")?;
        Ok(match (robhold, ufprog, ufmec, uframe, oframe) {
            (Some(robhold), Some(ufprog), Some(ufmec), Some(uframe), Some(oframe)) => {
                Some(WobjData {
                    span: v.span(),
                    robhold,
                    ufprog,
                    ufmec,
                    uframe,
                    oframe,
                })
            }
            _ => None,
        })
    }

    fn speed_data(&self, v: &Val) -> Result<Option<SpeedData>, E<'a>> {
        Ok(self
            .nums::<4>(v, SPEEDDATA_SHAPE, "it")?
            .map(|values| SpeedData {
                span: v.span(),
                values,
            }))
    }

    fn zone_data(&self, v: &Val) -> Result<Option<ZoneData>, E<'a>> {
        let s = ZONEDATA_SHAPE;
        let Some(parts) = self.list(v, 7, s, "it")? else {
            return Ok(None);
        };
        let Some((f, rest)) = parts.split_first() else {
            return Ok(None);
        };
        let finep = self.boolean(f, &format!("{s}: finep must be TRUE or FALSE"))?;
        let mut values = Vec::with_capacity(6);
        for x in rest {
            match self.num(x, s)? {
                Some(n) => values.push(n),
                None => return Ok(None),
            }
        }
        Ok(match (finep, <[Number; 6]>::try_from(values)) {
            (Some(finep), Ok(values)) => Some(ZoneData {
                span: v.span(),
                finep,
                values,
            }),
            _ => None,
        })
    }

    /// `v` must be a list of `n` items; a name or expression gives `None`.
    fn list<'v>(
        &self,
        v: &'v Val,
        n: usize,
        shape: &str,
        what: &str,
    ) -> Result<Option<&'v [Val]>, E<'a>> {
        match v {
            Val::List { items, span } => {
                if items.len() == n {
                    Ok(Some(items))
                } else {
                    Err(self.err_found(
                        span.start,
                        &format!("{shape}: {what} has {} values, expected {n}", items.len()),
                    ))
                }
            }
            Val::Word { .. } | Val::Expr { .. } => Ok(None),
            Val::Num(_) | Val::Str { .. } => Err(self.err_found(
                v.span().start,
                &format!("{shape}: {what} must be an aggregate [ … ] of {n} values"),
            )),
        }
    }

    /// `v` must be a list of `N` numbers.
    fn nums<const N: usize>(
        &self,
        v: &Val,
        shape: &str,
        what: &str,
    ) -> Result<Option<[Number; N]>, E<'a>> {
        let Some(items) = self.list(v, N, shape, what)? else {
            return Ok(None);
        };
        let mut out = Vec::with_capacity(N);
        for item in items {
            match self.num(item, shape)? {
                Some(n) => out.push(n),
                None => return Ok(None),
            }
        }
        Ok(<[Number; N]>::try_from(out).ok())
    }

    /// `v` must be a number; the name of a `CONST num` of the module
    /// declared before gives its value (at the name's span); another name
    /// or an expression gives `None`.
    fn num(&self, v: &Val, shape: &str) -> Result<Option<Number>, E<'a>> {
        match v {
            Val::Num(n) => Ok(Some(n.clone())),
            Val::Word { text, span } => Ok(self
                .consts
                .borrow()
                .iter()
                .find(|(c, _)| c.eq_ignore_ascii_case(text))
                .map(|&(_, value)| Number {
                    value,
                    span: span.clone(),
                })),
            Val::Expr { .. } => Ok(None),
            Val::List { .. } | Val::Str { .. } => {
                Err(self.err_found(v.span().start, &format!("{shape}: expected a number here")))
            }
        }
    }

    /// `v` must be `TRUE` or `FALSE`; another name or expression gives `None`.
    fn boolean(&self, v: &Val, what: &str) -> Result<Option<bool>, E<'a>> {
        match v {
            Val::Word { text, .. } if text.eq_ignore_ascii_case("TRUE") => Ok(Some(true)),
            Val::Word { text, .. } if text.eq_ignore_ascii_case("FALSE") => Ok(Some(false)),
            Val::Word { .. } | Val::Expr { .. } => Ok(None),
            _ => Err(self.err_found(v.span().start, what)),
        }
    }
}

/// Deepest nesting of parentheses [`const_int`] evaluates.
const MAX_CONST_DEPTH: usize = 8;

/// The value of a constant integer expression `text` (an array size such
/// as `MAX_BUFFER` or `N+1`): integer literals, names of `CONST num`
/// declarations among `decls` with an integer value, `+`, `-`, `*`, `DIV`
/// and parentheses. `None` for anything else, or on overflow.
pub(super) fn const_int(text: &str, decls: &[Decl]) -> Option<i64> {
    let mut e = ConstExpr {
        b: text.as_bytes(),
        k: 0,
        decls,
    };
    let v = e.sum(0)?;
    e.blanks();
    (e.k == e.b.len()).then_some(v)
}

/// The state of [`const_int`]: the text and the position in it.
struct ConstExpr<'t> {
    b: &'t [u8],
    k: usize,
    decls: &'t [Decl],
}

impl<'t> ConstExpr<'t> {
    fn blanks(&mut self) {
        while self.b.get(self.k).is_some_and(u8::is_ascii_whitespace) {
            self.k += 1;
        }
    }

    fn word(&mut self) -> &'t str {
        let start = self.k;
        while self
            .b
            .get(self.k)
            .is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_')
        {
            self.k += 1;
        }
        let b: &'t [u8] = self.b;
        std::str::from_utf8(b.get(start..self.k).unwrap_or_default()).unwrap_or("")
    }

    fn sum(&mut self, depth: usize) -> Option<i64> {
        let mut v = self.product(depth)?;
        loop {
            self.blanks();
            match self.b.get(self.k) {
                Some(b'+') => {
                    self.k += 1;
                    v = v.checked_add(self.product(depth)?)?;
                }
                Some(b'-') => {
                    self.k += 1;
                    v = v.checked_sub(self.product(depth)?)?;
                }
                _ => return Some(v),
            }
        }
    }

    fn product(&mut self, depth: usize) -> Option<i64> {
        let mut v = self.factor(depth)?;
        loop {
            self.blanks();
            if self.b.get(self.k) == Some(&b'*') {
                self.k += 1;
                v = v.checked_mul(self.factor(depth)?)?;
                continue;
            }
            let save = self.k;
            if self.word().eq_ignore_ascii_case("DIV") {
                let d = self.factor(depth)?;
                v = v.checked_div(d)?;
                continue;
            }
            self.k = save;
            return Some(v);
        }
    }

    fn factor(&mut self, depth: usize) -> Option<i64> {
        self.blanks();
        match *self.b.get(self.k)? {
            b'-' if depth < MAX_CONST_DEPTH => {
                self.k += 1;
                self.factor(depth + 1)?.checked_neg()
            }
            b'+' if depth < MAX_CONST_DEPTH => {
                self.k += 1;
                self.factor(depth + 1)
            }
            b'(' if depth < MAX_CONST_DEPTH => {
                self.k += 1;
                let v = self.sum(depth + 1)?;
                self.blanks();
                (self.b.get(self.k) == Some(&b')')).then_some(())?;
                self.k += 1;
                Some(v)
            }
            c if c.is_ascii_digit() => self.word().parse::<i64>().ok(),
            c if c.is_ascii_alphabetic() => {
                let name = self.word();
                let d = self
                    .decls
                    .iter()
                    .find(|d| d.name.eq_ignore_ascii_case(name))?;
                match (&d.storage, &d.data_type, &d.value, d.dims.is_empty()) {
                    (Storage::Const, DataType::Num, Some(DataValue::Num(n)), true)
                        if n.value.fract() == 0.0 && n.value.abs() < 1e15 =>
                    {
                        Some(n.value as i64)
                    }
                    _ => None,
                }
            }
            _ => None,
        }
    }
}
