//! The Rust code generated from the messages: one struct per message with
//! its `Default` (the `.msg` default values), its `MessageType` constant
//! (name and RIHS01 hash) and its `RosMessage` implementation (CDR write,
//! read, first non-finite field); and the full definitions of the types a
//! topic carries.
//!
//! Encoding and decoding are flattened: a message reads and writes its
//! primitives in declaration order, depth first, which is CDR's layout.
//! Errors name a field by its path, except that a nested message of
//! `float64` scalars only (`Vector3`, `Point`, `Quaternion`) is named as a
//! whole (`twist.linear`, `pose.pose.orientation`).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use crate::describe::{full_definition, type_hash};
use crate::msg::{Base, Field, Msg, Primitive};

/// One primitive (or fixed-size array of primitives) of a flattened
/// message, or one unbounded sequence of a nested message (written and read
/// by that message's own codec, element by element).
struct Slot {
    /// Path from the message, `pose.pose.position.x`.
    path: String,
    kind: SlotKind,
    /// The field name errors give.
    name: String,
}

enum SlotKind {
    Prim(Primitive, Option<usize>),
    /// A sequence of the nested message of this Rust name.
    Sequence,
}

/// A field name as a Rust identifier: a keyword (`type`) raw (`r#type`).
fn ident(name: &str) -> String {
    const KEYWORDS: [&str; 10] = [
        "type", "match", "loop", "move", "ref", "self", "struct", "enum", "fn", "impl",
    ];
    if KEYWORDS.contains(&name) {
        format!("r#{name}")
    } else {
        name.to_owned()
    }
}

/// A field path (`header.stamp`) as Rust accesses it, each name an [`ident`].
fn access(path: &str) -> String {
    path.split('.').map(ident).collect::<Vec<_>>().join(".")
}

/// `TwistStamped` → `TWIST_STAMPED`, `Vector3` → `VECTOR3`.
pub(crate) fn screaming(ty: &str) -> String {
    let mut out = String::new();
    for (i, c) in ty.chars().enumerate() {
        if c.is_ascii_uppercase() && i > 0 {
            out.push('_');
        }
        out.push(c.to_ascii_uppercase());
    }
    out
}

fn nested<'a>(all: &'a BTreeMap<String, Msg>, f: &Field) -> Option<&'a Msg> {
    match &f.base {
        Base::Nested(n) => Some(&all[n]),
        Base::Primitive(_) => None,
    }
}

/// Whether every field is a scalar `float64`.
fn is_float_leaf(msg: &Msg) -> bool {
    msg.fields
        .iter()
        .all(|f| f.base == Base::Primitive(Primitive::Float64) && f.array.is_none())
}

fn flatten(msg: &Msg, all: &BTreeMap<String, Msg>, prefix: &str, out: &mut Vec<Slot>) {
    let whole = !prefix.is_empty() && is_float_leaf(msg);
    for f in &msg.fields {
        let path = if prefix.is_empty() {
            f.name.clone()
        } else {
            format!("{prefix}.{}", f.name)
        };
        match (&f.base, nested(all, f)) {
            (Base::Primitive(prim), _) => out.push(Slot {
                name: if whole {
                    prefix.to_owned()
                } else {
                    path.clone()
                },
                path,
                kind: SlotKind::Prim(*prim, f.array),
            }),
            (Base::Nested(_), Some(_)) if f.sequence => out.push(Slot {
                name: path.clone(),
                path,
                kind: SlotKind::Sequence,
            }),
            (Base::Nested(_), Some(inner)) => flatten(inner, all, &path, out),
            (Base::Nested(n), None) => panic!("{}: unknown type {n}", msg.ty),
        }
    }
}

/// The expression reading `msg` (at `prefix`) from `r`, field by field.
fn read_expr(msg: &Msg, all: &BTreeMap<String, Msg>, prefix: &str, indent: &str) -> String {
    let whole = !prefix.is_empty() && is_float_leaf(msg);
    let inner = format!("{indent}    ");
    let mut out = format!("{} {{\n", msg.ty);
    for f in &msg.fields {
        let path = if prefix.is_empty() {
            f.name.clone()
        } else {
            format!("{prefix}.{}", f.name)
        };
        let value = match (&f.base, nested(all, f)) {
            (Base::Primitive(prim), _) => {
                let name = if whole { prefix } else { &path };
                let read = match prim {
                    Primitive::Bool => format!("r.read_bool({name:?})?"),
                    Primitive::Uint8 => format!("r.read_u8({name:?})?"),
                    Primitive::Int32 => format!("r.read_i32({name:?})?"),
                    Primitive::Uint32 => format!("r.read_u32({name:?})?"),
                    Primitive::Float64 => format!("r.read_f64({name:?})?"),
                    Primitive::String => format!("r.read_string({name:?})?.to_owned()"),
                };
                match f.array {
                    Some(_) => format!(
                        "{{\n{inner}    let mut a = {};\n{inner}    for v in &mut a {{\n{inner}        *v = {read};\n{inner}    }}\n{inner}    a\n{inner}}}",
                        default_value(f)
                    ),
                    None => read,
                }
            }
            (Base::Nested(_), Some(nested_msg)) if f.sequence => format!(
                "{{\n{inner}    let n = r.read_sequence_len({path:?})?;\n{inner}    let mut v = Vec::with_capacity(n);\n{inner}    for _ in 0..n {{\n{inner}        v.push({}::read_cdr(r)?);\n{inner}    }}\n{inner}    v\n{inner}}}",
                nested_msg.ty
            ),
            (Base::Nested(_), Some(nested_msg)) => read_expr(nested_msg, all, &path, &inner),
            (Base::Nested(n), None) => panic!("{}: unknown type {n}", msg.ty),
        };
        let _ = writeln!(out, "{inner}{}: {value},", ident(&f.name));
    }
    out.push_str(indent);
    out.push('}');
    out
}

/// Whether `msg` (and what it nests) has no `string`: the struct is `Copy`.
fn is_copy(msg: &Msg, all: &BTreeMap<String, Msg>) -> bool {
    msg.fields.iter().all(|f| match nested(all, f) {
        Some(_) if f.sequence => false,
        Some(inner) => is_copy(inner, all),
        None => f.base != Base::Primitive(Primitive::String),
    })
}

/// Whether `msg` (and what it nests) has no float: the struct is `Eq`.
fn is_eq(msg: &Msg, all: &BTreeMap<String, Msg>) -> bool {
    msg.fields.iter().all(|f| match nested(all, f) {
        Some(inner) => is_eq(inner, all),
        None => f.base != Base::Primitive(Primitive::Float64),
    })
}

fn rust_type(f: &Field) -> String {
    let scalar = match &f.base {
        Base::Primitive(p) => p.rust().to_owned(),
        Base::Nested(n) => n.rsplit('/').next().unwrap_or(n).to_owned(),
    };
    match (f.array, f.sequence) {
        (Some(n), _) => format!("[{scalar}; {n}]"),
        (None, true) => format!("Vec<{scalar}>"),
        (None, false) => scalar,
    }
}

/// The Rust expression of a field's default value.
fn default_value(f: &Field) -> String {
    let scalar = match (&f.base, &f.default) {
        (Base::Primitive(Primitive::Float64), Some(d)) => {
            let v: f64 = d
                .parse()
                .unwrap_or_else(|_| panic!("default `{d}` of {}", f.name));
            format!("{v:?}")
        }
        (Base::Primitive(Primitive::Int32 | Primitive::Uint32 | Primitive::Uint8), Some(d)) => {
            d.clone()
        }
        (Base::Primitive(Primitive::Bool), Some(d)) => (d == "true" || d == "1").to_string(),
        (Base::Primitive(Primitive::Bool), None) => "false".to_owned(),
        (Base::Primitive(Primitive::String), Some(d)) => format!("{d:?}.to_owned()"),
        (Base::Primitive(Primitive::Float64), None) => "0.0".to_owned(),
        (Base::Primitive(Primitive::Int32 | Primitive::Uint32 | Primitive::Uint8), None) => {
            "0".to_owned()
        }
        (Base::Primitive(Primitive::String), None) => "String::new()".to_owned(),
        (Base::Nested(_), _) if f.sequence => return "Vec::new()".to_owned(),
        (Base::Nested(_), _) => "Default::default()".to_owned(),
    };
    match f.array {
        Some(n) => format!("[{scalar}; {n}]"),
        None => scalar,
    }
}

/// Doc comment lines, indented; a line of the `.msg` comments that is a bare
/// URL becomes a link (`<https://…>`), as rustdoc wants it.
fn doc(out: &mut String, indent: &str, lines: &[String]) {
    for l in lines {
        let url = l.starts_with("http://") || l.starts_with("https://");
        let l = if url && !l.contains(char::is_whitespace) {
            format!("<{l}>")
        } else {
            l.clone()
        };
        let _ = writeln!(out, "{indent}///{}{l}", if l.is_empty() { "" } else { " " });
    }
}

/// The generated `msgs` items of every message.
pub(crate) fn msgs(all: &BTreeMap<String, Msg>) -> String {
    let mut out = String::new();
    for msg in all.values() {
        emit_struct(&mut out, msg, all);
        emit_message(&mut out, msg, all);
    }
    out
}

fn emit_struct(out: &mut String, msg: &Msg, all: &BTreeMap<String, Msg>) {
    let name = &msg.ty;
    let mut head = vec![format!(
        "`{}`, generated from `msg/{}/{}.msg`.",
        msg.full_name(),
        msg.package,
        msg.ty
    )];
    if !msg.doc.is_empty() {
        head.push(String::new());
        head.extend(msg.doc.iter().cloned());
    }
    doc(out, "", &head);
    // Derived `Default` unless a field has a default value or a long array.
    let derive_default = msg
        .fields
        .iter()
        .all(|f| f.default.is_none() && f.array.is_none_or(|n| n <= 32));
    let mut derives = vec!["Debug", "Clone"];
    if is_copy(msg, all) {
        derives.push("Copy");
    }
    derives.push("PartialEq");
    if is_eq(msg, all) {
        derives.push("Eq");
    }
    if derive_default {
        derives.push("Default");
    }
    let _ = writeln!(
        out,
        "#[derive({})]\npub struct {name} {{",
        derives.join(", ")
    );
    for f in &msg.fields {
        if f.doc.is_empty() {
            doc(out, "    ", &[format!("`{}`.", f.name)]);
        } else {
            doc(out, "    ", &f.doc);
        }
        let _ = writeln!(out, "    pub {}: {},", ident(&f.name), rust_type(f));
    }
    out.push_str("}\n\n");
    if !msg.constants.is_empty() {
        let _ = writeln!(out, "impl {name} {{");
        for c in &msg.constants {
            if c.doc.is_empty() {
                doc(out, "    ", &[format!("`{}`.", c.name)]);
            } else {
                doc(out, "    ", &c.doc);
            }
            let _ = writeln!(
                out,
                "    pub const {}: {} = {};",
                c.name,
                c.prim.rust(),
                c.value
            );
        }
        out.push_str("}\n\n");
    }
    if !derive_default {
        let _ = writeln!(
            out,
            "impl Default for {name} {{\n    /// The `.msg`'s default values.\n    fn default() -> {name} {{\n        {name} {{"
        );
        for f in &msg.fields {
            let _ = writeln!(out, "            {}: {},", ident(&f.name), default_value(f));
        }
        out.push_str("        }\n    }\n}\n\n");
    }
}

/// The `MessageType` constant of `msg` and its `RosMessage` implementation.
fn emit_message(out: &mut String, msg: &Msg, all: &BTreeMap<String, Msg>) {
    let name = &msg.ty;
    let konst = screaming(name);
    let _ = writeln!(
        out,
        "/// `{full}` (Jazzy): name and RIHS01 type hash.\npub const {konst}: MessageType = MessageType {{\n    name: \"{full}\",\n    hash: \"{hash}\",\n}};\n",
        full = msg.full_name(),
        hash = type_hash(msg, all),
    );
    let mut slots = Vec::new();
    flatten(msg, all, "", &mut slots);
    let _ = writeln!(
        out,
        "impl RosMessage for {name} {{\n    const TYPE: MessageType = {konst};\n"
    );
    emit_write_cdr(out, &slots);
    // Read: a struct expression, whose fields Rust evaluates in order.
    let _ = writeln!(
        out,
        "    fn read_cdr(r: &mut CdrReader<'_>) -> Result<{name}, CdrError> {{\n        Ok({})\n    }}\n",
        read_expr(msg, all, "", "        ")
    );
    emit_first_non_finite(out, &slots);
    out.push_str("}\n\n");
}

/// The `write_cdr` method: every slot written in order.
fn emit_write_cdr(out: &mut String, slots: &[Slot]) {
    out.push_str("    fn write_cdr(&self, w: &mut CdrWriter<'_>) {\n");
    for s in slots {
        let (prim, array) = match s.kind {
            SlotKind::Prim(p, a) => (p, a),
            SlotKind::Sequence => {
                let _ = writeln!(
                    out,
                    "        w.write_sequence_len(self.{p}.len());\n        for e in &self.{p} {{\n            e.write_cdr(w);\n        }}",
                    p = access(&s.path)
                );
                continue;
            }
        };
        emit_write_prim(out, &s.path, prim, array);
    }
    out.push_str("    }\n\n");
}

/// The statement writing the primitive (or fixed-size array) at `path`.
fn emit_write_prim(out: &mut String, path: &str, prim: Primitive, array: Option<usize>) {
    let call = match prim {
        Primitive::Bool => "w.write_bool(v)",
        Primitive::Uint8 => "w.write_u8(v)",
        Primitive::Int32 => "w.write_i32(v)",
        Primitive::Uint32 => "w.write_u32(v)",
        Primitive::Float64 => "w.write_f64(v)",
        Primitive::String => "w.write_string(v)",
    };
    let by_ref = prim == Primitive::String;
    let _ = match array {
        Some(_) if by_ref => writeln!(
            out,
            "        for v in &self.{} {{\n            {call};\n        }}",
            access(path)
        ),
        Some(_) => writeln!(
            out,
            "        for &v in &self.{} {{\n            {call};\n        }}",
            access(path)
        ),
        None if by_ref => writeln!(
            out,
            "        {};",
            call.replace("(v)", &format!("(&self.{})", access(path)))
        ),
        None => writeln!(
            out,
            "        {};",
            call.replace("(v)", &format!("(self.{})", access(path)))
        ),
    };
}

/// The `first_non_finite` method: float slots grouped by the name errors
/// give, then each sequence's elements.
fn emit_first_non_finite(out: &mut String, slots: &[Slot]) {
    out.push_str("    fn first_non_finite(&self) -> Option<&'static str> {\n");
    let floats: Vec<&Slot> = slots
        .iter()
        .filter(|s| matches!(s.kind, SlotKind::Prim(Primitive::Float64, _)))
        .collect();
    for group in floats.chunk_by(|a, b| a.name == b.name) {
        let checks: Vec<String> = group
            .iter()
            .map(|s| match s.kind {
                SlotKind::Prim(_, Some(_)) => {
                    format!("self.{}.iter().all(|v| v.is_finite())", access(&s.path))
                }
                _ => format!("self.{}.is_finite()", access(&s.path)),
            })
            .collect();
        let test = match checks.as_slice() {
            [one] => format!("!{one}"),
            all => format!("!({})", all.join(" && ")),
        };
        let _ = writeln!(
            out,
            "        if {test} {{\n            return Some({:?});\n        }}",
            group[0].name
        );
    }
    for s in slots
        .iter()
        .filter(|s| matches!(s.kind, SlotKind::Sequence))
    {
        let _ = writeln!(
            out,
            "        if let Some(f) = self.{}.iter().find_map(RosMessage::first_non_finite) {{\n            return Some(f);\n        }}",
            access(&s.path)
        );
    }
    out.push_str("        None\n    }\n");
}

/// The generated `definitions` items: a full definition per topic type and
/// the table of them.
pub(crate) fn definitions(all: &BTreeMap<String, Msg>, topic_types: &[&str]) -> String {
    let mut out = String::new();
    let mut table = Vec::new();
    for short in topic_types {
        let msg = all
            .get(*short)
            .unwrap_or_else(|| panic!("topic type {short} has no .msg under msg/"));
        let konst = screaming(&msg.ty);
        let _ = writeln!(
            out,
            "/// The full definition of `{}`.\npub const {konst}_DEFINITION: &str = {:?};\n",
            msg.full_name(),
            full_definition(msg, all)
        );
        table.push(format!("    (crate::msgs::{konst}, {konst}_DEFINITION),"));
    }
    let _ = writeln!(
        out,
        "/// The message types a topic may carry, with their full definitions.\npub const TOPIC_TYPES: &[(MessageType, &str)] = &[\n{}\n];",
        table.join("\n")
    );
    out
}
