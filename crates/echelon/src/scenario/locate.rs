//! From byte offsets to `line:column` and field paths, and back, over the
//! spanned parse of a scenario file, so that every error names where it is.
//! [`Locator`] is the one place that turns a field path into a location: the
//! file's `line:column`, or the command line for a value a flag set.

use std::fmt::{self, Display};
use std::ops::Range;

use toml::Spanned;
use toml::de::{DeTable, DeValue};

use super::schema::PoseSpec;
use crate::check;
use crate::error::{Location, ParamError, ScenarioError};
use crate::model::State;

/// One step of a field path.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Seg {
    /// A table key.
    Key(String),
    /// A 0-based array index (shown 1-based: agents count from 1).
    Index(usize),
}

/// A dotted field path such as `agents[3].offset.x`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub(crate) struct FieldPath(pub(crate) Vec<Seg>);

impl FieldPath {
    pub(crate) fn key(&self, k: &str) -> FieldPath {
        let mut p = self.clone();
        p.0.push(Seg::Key(k.to_owned()));
        p
    }

    pub(crate) fn index(&self, i: usize) -> FieldPath {
        let mut p = self.clone();
        p.0.push(Seg::Index(i));
        p
    }

    /// This path followed by a dotted relative one (`start.x`).
    pub(crate) fn join(&self, rel: &str) -> FieldPath {
        let mut p = self.clone();
        p.0.extend(rel.split('.').map(|k| Seg::Key(k.to_owned())));
        p
    }
}

/// Which fields the command line set, and by which flag (`sim.dt` ← `--dt`).
pub(crate) type Origins = Vec<(FieldPath, &'static str)>;

/// Turns field paths into locations in one scenario source.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Locator<'a> {
    source: &'a str,
    origin: &'a str,
    flags: &'a [(FieldPath, &'static str)],
}

impl<'a> Locator<'a> {
    /// Errors in `source`, named `origin`; `flags` are the fields the command line set.
    pub(crate) fn new(
        source: &'a str,
        origin: &'a str,
        flags: &'a [(FieldPath, &'static str)],
    ) -> Locator<'a> {
        Locator {
            source,
            origin,
            flags,
        }
    }

    /// An error at `path`: `file:line:column: path: message`, or
    /// `command line: --flag: message` when a flag set the value.
    pub(crate) fn error(&self, path: &FieldPath, message: impl Display) -> ScenarioError {
        if let Some(flag) = self.flag(path) {
            return ScenarioError::of_flag(flag, message);
        }
        ScenarioError {
            location: self.place(path),
            field: path.to_string(),
            message: message.to_string(),
        }
    }

    /// The flag that set the value at `path`, if the command line did.
    pub(crate) fn flag(&self, path: &FieldPath) -> Option<&'static str> {
        self.flags.iter().find(|(p, _)| p == path).map(|(_, f)| *f)
    }

    /// Where `path` (or the deepest part of it that exists) is in the file:
    /// `file:line:column`, or the file alone when none of it is.
    pub(crate) fn place(&self, path: &FieldPath) -> Location {
        let (line, column) = Spans::new(self.source)
            .span_of(path)
            .map_or((0, 0), |s| line_col(self.source, s.start));
        Location {
            file: self.origin.to_owned(),
            line,
            column,
        }
    }

    /// A refused value at `path`: `value reason`.
    /// The state a `{ x, y, theta | theta_deg [, v, omega] }` table gives
    /// (`speeds`: whether `v`, `omega` are allowed), its refusals at `path`.
    pub(crate) fn pose(
        &self,
        p: &PoseSpec,
        path: &FieldPath,
        speeds: bool,
    ) -> Result<State, ScenarioError> {
        let (theta, theta_key) = match (p.theta, p.theta_deg) {
            (Some(_), Some(_)) => {
                return Err(self.error(
                    &path.key("theta_deg"),
                    "give either theta (radians) or theta_deg (degrees), not both",
                ));
            }
            (Some(t), None) => (t, "theta"),
            (None, Some(d)) => (d.to_radians(), "theta_deg"),
            (None, None) => {
                return Err(self.error(
                    path,
                    "missing field `theta` (radians) or `theta_deg` (degrees)",
                ));
            }
        };
        if !speeds && (p.v.is_some() || p.omega.is_some()) {
            let which = if p.v.is_some() { "v" } else { "omega" };
            return Err(self.error(
                &path.key(which),
                "this pose takes no speed: only an agent's `start` has `v` and `omega`",
            ));
        }
        let (v, omega) = (p.v.unwrap_or(0.0), p.omega.unwrap_or(0.0));
        for (k, value) in [
            ("x", p.x),
            ("y", p.y),
            (theta_key, theta),
            ("v", v),
            ("omega", omega),
        ] {
            check::finite(k, value).map_err(|e| self.param(&path.key(k), &e))?;
        }
        Ok(State {
            x: p.x,
            y: p.y,
            theta,
            v,
            omega,
        })
    }

    pub(crate) fn param(&self, path: &FieldPath, e: &ParamError) -> ScenarioError {
        self.error(path, format!("{} {}", crate::error::num(e.value), e.reason))
    }

    /// A TOML syntax or type error, at the field it is in.
    pub(crate) fn parse_error(&self, e: &toml::de::Error) -> ScenarioError {
        let source = self.source;
        let offset = e.span().map_or(0, |s| s.start);
        let spans = Spans::new(source);
        let mut field = spans.path_at(offset);
        // After a syntax error the recovered spans are only trusted when the
        // field's key is on the error's own line.
        let syntax_error = DeTable::parse(source).is_err();
        let key_on_error_line = spans
            .key_span_of(&field)
            .is_some_and(|s| line_col(source, s.start).0 == line_col(source, offset).0);
        if syntax_error && !key_on_error_line {
            field = FieldPath::default();
        }
        let message = e.message().trim().to_owned();
        if let Some(missing) = message
            .strip_prefix("missing field `")
            .and_then(|m| m.strip_suffix('`'))
        {
            // The error spans the table that lacks the field: the whole
            // document for a top-level one (whose first key is not it).
            if e.span().is_none_or(|s| spans.is_whole(&s)) {
                field = FieldPath::default();
            }
            field = field.key(missing);
        }
        let (line, column) = e.span().map_or((0, 0), |s| line_col(source, s.start));
        ScenarioError {
            location: Location {
                file: self.origin.to_owned(),
                line,
                column,
            },
            field: field.to_string(),
            message,
        }
    }
}

/// An error that is not at a field of the file: reading it, finding it.
pub(crate) fn whole_file_error(file: &str, message: impl Display) -> ScenarioError {
    ScenarioError {
        location: Location {
            file: file.to_owned(),
            line: 0,
            column: 0,
        },
        field: String::new(),
        message: message.to_string(),
    }
}

/// `FieldPath::from("agents").index(2).key("offset")`.
impl From<&str> for FieldPath {
    fn from(s: &str) -> FieldPath {
        FieldPath(s.split('.').map(|k| Seg::Key(k.to_owned())).collect())
    }
}

impl fmt::Display for FieldPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (n, seg) in self.0.iter().enumerate() {
            match seg {
                Seg::Key(k) if n == 0 => write!(f, "{k}")?,
                Seg::Key(k) => write!(f, ".{k}")?,
                Seg::Index(i) => write!(f, "[{}]", i + 1)?,
            }
        }
        Ok(())
    }
}

/// 1-based line and column (in characters) of a byte offset.
pub(crate) fn line_col(src: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(src.len());
    let before = &src[..src.floor_char_boundary(offset)];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

/// The spanned document of a scenario source.
pub(crate) struct Spans<'a> {
    root: Option<Spanned<DeTable<'a>>>,
}

impl<'a> Spans<'a> {
    /// Parses what it can: even a file with a syntax error yields the spans of
    /// the keys around it.
    pub(crate) fn new(src: &'a str) -> Spans<'a> {
        Spans {
            root: Some(DeTable::parse_recoverable(src).0),
        }
    }

    /// Whether `span` is the whole document's (what an error in the
    /// top-level table spans).
    pub(crate) fn is_whole(&self, span: &Range<usize>) -> bool {
        self.root.as_ref().is_some_and(|r| r.span() == *span)
    }

    /// The span of the value at `path` (or of the deepest part of it that exists).
    pub(crate) fn span_of(&self, path: &FieldPath) -> Option<Range<usize>> {
        self.find(path).map(|(_, value)| value)
    }

    /// The span of the last key of `path`, if it exists in the file.
    pub(crate) fn key_span_of(&self, path: &FieldPath) -> Option<Range<usize>> {
        self.find(path).and_then(|(key, _)| key)
    }

    /// Key and value spans of the deepest existing part of `path`.
    fn find(&self, path: &FieldPath) -> Option<(Option<Range<usize>>, Range<usize>)> {
        let root = self.root.as_ref()?;
        let mut table: &DeTable<'_> = root.get_ref();
        let mut array: Option<&[Spanned<DeValue<'_>>]> = None;
        let mut found = None;
        for seg in &path.0 {
            let (key, value) = match (seg, array) {
                (Seg::Key(k), None) => match table.iter().find(|(key, _)| key.get_ref() == k) {
                    Some((key, v)) => (Some(key.span()), v),
                    None => break,
                },
                (Seg::Index(i), Some(items)) => match items.get(*i) {
                    Some(v) => (None, v),
                    None => break,
                },
                _ => break,
            };
            found = Some((key, value.span()));
            array = None;
            match value.get_ref() {
                DeValue::Table(t) => table = t,
                DeValue::Array(a) => array = Some(a),
                _ => {}
            }
        }
        found
    }

    /// The deepest field whose key or value contains `offset`.
    pub(crate) fn path_at(&self, offset: usize) -> FieldPath {
        let mut path = FieldPath::default();
        if let Some(root) = &self.root {
            search_table(root.get_ref(), offset, &mut path);
        }
        path
    }
}

fn contains(span: &Range<usize>, offset: usize) -> bool {
    span.start <= offset && offset < span.end.max(span.start + 1)
}

fn search_table(t: &DeTable<'_>, offset: usize, path: &mut FieldPath) -> bool {
    for (k, v) in t.iter() {
        path.0.push(Seg::Key(k.get_ref().to_string()));
        if search_value(v.get_ref(), offset, path)
            || contains(&k.span(), offset)
            || contains(&v.span(), offset)
        {
            return true;
        }
        path.0.pop();
    }
    false
}

fn search_value(v: &DeValue<'_>, offset: usize, path: &mut FieldPath) -> bool {
    match v {
        DeValue::Table(t) => search_table(t, offset, path),
        DeValue::Array(items) => {
            for (i, item) in items.iter().enumerate() {
                path.0.push(Seg::Index(i));
                if search_value(item.get_ref(), offset, path) || contains(&item.span(), offset) {
                    return true;
                }
                path.0.pop();
            }
            false
        }
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SRC: &str = "[r.circle]\nspeed = 1\n\n[[agents]]\nname = \"a\"\nx = 1.0\n\n[[agents]]\nname = \"b\"\nx = \"bad\"\n";

    #[test]
    fn paths_and_spans_agree() {
        let s = Spans::new(SRC);
        let p = FieldPath::from("agents").index(1).key("x");
        assert_eq!(p.to_string(), "agents[2].x");
        let span = s.span_of(&p).unwrap();
        assert_eq!(&SRC[span.clone()], "\"bad\"");
        assert_eq!(s.path_at(span.start), p);
        assert_eq!(line_col(SRC, span.start), (10, 5));
        assert_eq!(s.path_at(14).to_string(), "r.circle.speed");
    }

    /// A top-level table that is missing is named alone, not under the
    /// file's first key (`name.agents`, `sim.agents`), whatever comes first;
    /// a missing field of a table is still under it.
    #[test]
    fn a_missing_top_level_field_is_named_alone() {
        let sim = "[sim]\nduration = 1.0\ndt = 0.01\n";
        let reference =
            "[reference.line]\nspeed = 0.3\nstart = { x = 0.0, y = 0.0, theta = 0.0 }\n";
        let agent = "[[agents]]\nstart = { x = -1.0, y = 0.0, theta = 0.0 }\nleader = \"reference\"\noffset = { x = 0.5, y = 0.0 }\n";
        for head in ["", "name = \"n\"\n", "seed = 3\ndescription = \"d\"\n"] {
            for (src, missing) in [
                (format!("{head}{sim}{reference}"), "agents"),
                (format!("{head}{sim}{agent}"), "reference"),
                (format!("{head}{reference}{agent}"), "sim"),
            ] {
                let e = super::super::Scenario::parse(&src, "s.toml", None).unwrap_err();
                assert_eq!(e.field, missing, "{e}\n{src}");
            }
        }
        let e = super::super::Scenario::parse(
            &format!("[sim]\ndt = 0.01\n{reference}{agent}"),
            "s.toml",
            None,
        )
        .unwrap_err();
        assert_eq!(e.field, "sim.duration", "{e}");
    }
}
