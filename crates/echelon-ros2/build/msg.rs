//! Reads the `.msg` files under `msg/<package>/<Type>.msg`: the subset of
//! the ROS 2 interface language echelon's messages use (fields of `bool`,
//! `uint8`, `int32`, `uint32`, `float64`, `string` and nested messages,
//! fixed-size arrays of the numbers, unbounded sequences `T[]` of nested
//! messages, default values on scalars, integer constants `uint8 NAME=1`).
//! Anything else stops the build with the file and line, rather than being
//! guessed at.

use std::collections::BTreeMap;
use std::fs;
use std::path::Path;

/// A primitive field type the CDR codec (`src/cdr.rs`) reads and writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Primitive {
    Bool,
    Uint8,
    Int32,
    Uint32,
    Float64,
    String,
}

impl Primitive {
    fn parse(s: &str) -> Option<Primitive> {
        Some(match s {
            "bool" => Primitive::Bool,
            "uint8" => Primitive::Uint8,
            "int32" => Primitive::Int32,
            "uint32" => Primitive::Uint32,
            "float64" => Primitive::Float64,
            "string" => Primitive::String,
            _ => return None,
        })
    }

    /// `type_description_interfaces/msg/FieldType` id of the scalar.
    pub(crate) fn type_id(self) -> u8 {
        match self {
            Primitive::Uint8 => 3,
            Primitive::Int32 => 6,
            Primitive::Uint32 => 7,
            Primitive::Float64 => 11,
            Primitive::Bool => 15,
            Primitive::String => 17,
        }
    }

    /// The Rust type.
    pub(crate) fn rust(self) -> &'static str {
        match self {
            Primitive::Bool => "bool",
            Primitive::Uint8 => "u8",
            Primitive::Int32 => "i32",
            Primitive::Uint32 => "u32",
            Primitive::Float64 => "f64",
            Primitive::String => "String",
        }
    }
}

/// What a field holds, before the array suffix.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Base {
    Primitive(Primitive),
    /// A nested message, `package/Type`.
    Nested(String),
}

/// One field of a message.
#[derive(Debug, Clone)]
pub(crate) struct Field {
    pub(crate) name: String,
    pub(crate) base: Base,
    /// `Some(n)` for a fixed-size array `T[n]`.
    pub(crate) array: Option<usize>,
    /// An unbounded sequence `T[]` (of a nested message).
    pub(crate) sequence: bool,
    /// The default value as written in the `.msg` (scalars only).
    pub(crate) default: Option<String>,
    /// The comment lines just above the field.
    pub(crate) doc: Vec<String>,
}

/// One message type.
#[derive(Debug, Clone)]
pub(crate) struct Msg {
    /// `package`.
    pub(crate) package: String,
    /// `Type`.
    pub(crate) ty: String,
    /// The `.msg` file as it is (rosbag2 stores it verbatim).
    pub(crate) text: String,
    /// The comment lines at the top of the file, up to the first blank line
    /// or field.
    pub(crate) doc: Vec<String>,
    pub(crate) fields: Vec<Field>,
    /// Its constants (`uint8 BUMP=1`), which the type hash leaves out.
    pub(crate) constants: Vec<Constant>,
}

/// One constant of a message: `uint8 BUMP=1`.
#[derive(Debug, Clone)]
pub(crate) struct Constant {
    pub(crate) name: String,
    pub(crate) prim: Primitive,
    /// The value as written (an integer).
    pub(crate) value: String,
    /// The comment lines just above it.
    pub(crate) doc: Vec<String>,
}

impl Msg {
    /// `package/Type`, as `.msg` files and rosbag2's `MSG:` lines spell it.
    pub(crate) fn short_name(&self) -> String {
        format!("{}/{}", self.package, self.ty)
    }

    /// `package/msg/Type`, as ROS 2 names the type.
    pub(crate) fn full_name(&self) -> String {
        format!("{}/msg/{}", self.package, self.ty)
    }

    /// The `package/Type` names of the messages it nests, sorted, once each.
    pub(crate) fn dependencies(&self) -> Vec<String> {
        let mut deps: Vec<String> = self
            .fields
            .iter()
            .filter_map(|f| match &f.base {
                Base::Nested(n) => Some(n.clone()),
                Base::Primitive(_) => None,
            })
            .collect();
        deps.sort();
        deps.dedup();
        deps
    }
}

/// `package/Type` → `package/msg/Type`.
pub(crate) fn full_name(short: &str) -> String {
    match short.split_once('/') {
        Some((pkg, ty)) => format!("{pkg}/msg/{ty}"),
        None => short.to_owned(),
    }
}

/// Every `msg/<package>/<Type>.msg` under `root`, by `package/Type`.
pub(crate) fn read_all(root: &Path) -> BTreeMap<String, Msg> {
    let mut all = BTreeMap::new();
    for pkg in sorted_dir(root).into_iter().filter(|p| p.is_dir()) {
        let package = file_name(&pkg);
        for file in sorted_dir(&pkg) {
            let Some(ty) = file_name(&file).strip_suffix(".msg").map(str::to_owned) else {
                continue;
            };
            let text = fs::read_to_string(&file)
                .unwrap_or_else(|e| panic!("reading {}: {e}", file.display()));
            let msg =
                parse(&package, &ty, &text).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
            all.insert(msg.short_name(), msg);
        }
    }
    for msg in all.values() {
        for dep in msg.dependencies() {
            assert!(
                all.contains_key(&dep),
                "{} nests {dep}, which has no .msg under msg/",
                msg.short_name()
            );
        }
    }
    all
}

fn sorted_dir(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut entries: Vec<_> = fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("reading {}: {e}", dir.display()))
        .map(|e| {
            e.unwrap_or_else(|e| panic!("reading {}: {e}", dir.display()))
                .path()
        })
        .collect();
    entries.sort();
    entries
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .and_then(|n| n.to_str())
        .unwrap_or_else(|| panic!("{}: not a UTF-8 file name", path.display()))
        .to_owned()
}

/// Parses one `.msg` file of `package`.
pub(crate) fn parse(package: &str, ty: &str, text: &str) -> Result<Msg, String> {
    let mut fields: Vec<Field> = Vec::new();
    let mut constants: Vec<Constant> = Vec::new();
    // Comment lines not attached yet; the first block is the message's.
    let mut pending = Vec::new();
    let mut header_doc = None;
    for (i, line) in text.lines().enumerate() {
        let (code, comment) = match line.split_once('#') {
            Some((code, comment)) => (code.trim(), Some(comment.trim().to_owned())),
            None => (line.trim(), None),
        };
        if code.is_empty() {
            match comment {
                Some(c) => pending.push(c),
                None if header_doc.is_none() && !pending.is_empty() => {
                    header_doc = Some(std::mem::take(&mut pending));
                }
                None => pending.clear(),
            }
            continue;
        }
        if header_doc.is_none() {
            header_doc = Some(std::mem::take(&mut pending));
        }
        if code.contains('=') {
            let mut constant = parse_constant(code).map_err(|e| format!("line {}: {e}", i + 1))?;
            constant.doc = std::mem::take(&mut pending);
            constant.doc.extend(comment);
            constants.push(constant);
            continue;
        }
        let mut field = parse_field(package, code).map_err(|e| format!("line {}: {e}", i + 1))?;
        field.doc = std::mem::take(&mut pending);
        field.doc.extend(comment);
        fields.push(field);
    }
    if fields.is_empty() {
        return Err("a message without fields is not supported".to_owned());
    }
    Ok(Msg {
        package: package.to_owned(),
        ty: ty.to_owned(),
        text: text.to_owned(),
        doc: header_doc.unwrap_or_default(),
        fields,
        constants,
    })
}

/// `type NAME=value`: an integer constant.
fn parse_constant(code: &str) -> Result<Constant, String> {
    let (decl, value) = code.split_once('=').unwrap_or((code, ""));
    let mut parts = decl.split_whitespace();
    let (Some(ty), Some(name), None) = (parts.next(), parts.next(), parts.next()) else {
        return Err(format!("expected `type NAME=value`: `{code}`"));
    };
    let prim = Primitive::parse(ty)
        .filter(|p| matches!(p, Primitive::Uint8 | Primitive::Int32 | Primitive::Uint32))
        .ok_or_else(|| format!("constants are supported of integers only: `{code}`"))?;
    let value = value.trim();
    let fits = match prim {
        Primitive::Uint8 => value.parse::<u8>().is_ok(),
        Primitive::Int32 => value.parse::<i32>().is_ok(),
        _ => value.parse::<u32>().is_ok(),
    };
    if !fits {
        return Err(format!("`{value}` is not a {ty}: `{code}`"));
    }
    Ok(Constant {
        name: name.to_owned(),
        prim,
        value: value.to_owned(),
        doc: Vec::new(),
    })
}

/// `type name [default]`.
fn parse_field(package: &str, code: &str) -> Result<Field, String> {
    let mut parts = code.split_whitespace();
    let (Some(ty), Some(name)) = (parts.next(), parts.next()) else {
        return Err(format!("expected `type name`: `{code}`"));
    };
    let default = parts.next().map(str::to_owned);
    if parts.next().is_some() {
        return Err(format!("unexpected text after the default: `{code}`"));
    }
    let (base, array, sequence) = match ty.split_once('[') {
        None => (ty, None, false),
        Some((base, "]")) => (base, None, true),
        Some((base, rest)) => {
            let n = rest
                .strip_suffix(']')
                .and_then(|n| n.parse::<usize>().ok())
                .ok_or_else(|| {
                    format!(
                        "only fixed-size arrays `T[n]` and sequences `T[]` are supported: `{ty}`"
                    )
                })?;
            (base, Some(n), false)
        }
    };
    let base = match Primitive::parse(base) {
        Some(p) => Base::Primitive(p),
        None if base.chars().next().is_some_and(|c| c.is_ascii_uppercase()) => {
            Base::Nested(format!("{package}/{base}"))
        }
        None if base.contains('/') => Base::Nested(base.to_owned()),
        None => {
            return Err(format!(
                "type `{base}` is not supported (src/cdr.rs and build/msg.rs know \
                 bool, uint8, int32, uint32, float64, string and nested messages)"
            ));
        }
    };
    let numeric = matches!(base, Base::Primitive(p) if p != Primitive::String);
    if array.is_some() && !numeric {
        return Err(format!("arrays are supported of numbers only: `{code}`"));
    }
    if sequence && !matches!(base, Base::Nested(_)) {
        return Err(format!(
            "sequences are supported of nested messages only: `{code}`"
        ));
    }
    if default.is_some() && (array.is_some() || sequence || matches!(base, Base::Nested(_))) {
        return Err(format!("defaults are supported on scalars only: `{code}`"));
    }
    Ok(Field {
        name: name.to_owned(),
        base,
        array,
        sequence,
        default,
        doc: Vec::new(),
    })
}
