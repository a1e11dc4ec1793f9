//! Mutated built-in scenarios fed to the parser, the builder and a short run
//! (issue 20, item 4): numbers replaced by NaN, ±∞, 0, negatives, huge values
//! and values of the wrong type, strings replaced (some with newlines and
//! escape sequences), lines deleted or duplicated, tables deleted, unknown
//! keys added. Whatever the input:
//!
//! - nothing panics;
//! - every refusal is one line starting `fuzz.toml:LINE:COLUMN: ` (a real
//!   position: line and column ≥ 1) without control characters, and so is
//!   every warning;
//! - a run that ends `Ok` has a sane summary: final error, RMS error and peak
//!   torque finite and bounded (`SANE_ERROR`, `SANE_TORQUE`), final pose
//!   finite. A run that ends in an error (`SimError::Diverged`: a state no
//!   longer finite or out of its bounds, stopped by the divergence guard) is
//!   a proper refusal.
//!
//! Runs are capped to 0.5 s of simulated time and 2000 steps. Two corpus
//! runs: every single mutation of every built-in (about 19 000, 8 s in the
//! test profile), and 4000 random combinations of one to three (1.5 s).
//!
//! Waypoint tables (issue: a new user's bad inputs) get their own mutations —
//! times collapsed onto the previous one, huge jumps, NaN and other odd
//! cells, rows swapped or cut — written both as TOML `points` and as a CSV
//! file: each is refused at its place (the CSV's refusals at
//! `w.csv:LINE:COLUMN`), or builds a reference that is finite everywhere,
//! value and derivatives 1–4, no faster than the largest speed, and the same
//! from either format. The known
//! wrong answers of that issue are fixed cases.
#![allow(clippy::unwrap_used)] // tests fail loudly by design

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

use echelon::reference::{Order, Reference, Trajectory, Waypoints};
use echelon::scenario::{self, Overrides, Scenario};
use echelon::stats::Summary;
use proptest::prelude::*;

/// What the mutated source is called in errors.
const ORIGIN: &str = "fuzz.toml";
/// Longest run, simulated seconds.
const MAX_DURATION: f64 = 0.5;
/// Most steps of a run.
const MAX_STEPS: f64 = 2000.0;
/// Largest final and RMS error a sane run ends with, m: ten times the
/// largest plausible position (`start.x`, …, 1e6 m).
const SANE_ERROR: f64 = 1e7;
/// Largest peak wheel torque of a sane run, N m. The paper's law has no
/// torque limit and its torque grows with `K_e`, `K_z`, the error and the
/// mass: a Table I robot (27 kg) starting 1 km from its place in the
/// formation honestly asks for 1.4e6 N m. A run that diverges passes any
/// bound within a few steps.
const SANE_TORQUE: f64 = 1e12;

/// What a number is replaced by.
const NUMBERS: &[&str] = &[
    "nan",
    "+nan",
    "-nan",
    "inf",
    "+inf",
    "-inf",
    "0",
    "0.0",
    "-0.0",
    "-1",
    "-1.0",
    "-0.001",
    "1e-300",
    "5e-324",
    "1e-9",
    "1e9",
    "1e12",
    "1e15",
    "1e16",
    "1e30",
    "1e300",
    "-1e300",
    "1.7976931348623157e308",
    "9223372036854775807",
    "-9223372036854775808",
    "4294967296",
    "2",
    "1000",
    "\"1.0\"",
    "\"\"",
    "true",
    "{ a = 1 }",
    "{}",
    "[1.0, 2.0]",
    "[]",
    "1979-05-27",
];

/// What a string is replaced by.
const STRINGS: &[&str] = &[
    "\"\"",
    "\"x\"",
    "\"two\\nlines\"",
    "\"tab\\there\"",
    "\"\\u001b[31mred\"",
    "'''multi\nline'''",
    "\"agent1\"",
    "\"reference\"",
    "\"velocity\"",
    "\"ideal\"",
    "\"kinematic\"",
    "\"complete\"",
    "\"exact\"",
    "\"tracking\"",
    "0",
    "1",
    "-1",
    "nan",
    "[\"a\"]",
    "{ x = 1 }",
];

/// What an added key is.
const KEYS: &[&str] = &[
    "bogus = 1",
    "\"odd\\nkey\" = 1",
    "x = 1.0",
    "robot = \"agent2\"",
    "enabled = false",
    "name = \"n\"",
    "l = 0.1",
    // Sized an allocation before its plausible range was checked (an abort).
    "latency = 1e300",
];

#[derive(Debug, Clone)]
enum Mutation {
    /// The n-th number literal replaced (n modulo their count, as for the others).
    Number(usize, &'static str),
    /// The n-th string literal replaced.
    String(usize, &'static str),
    /// The n-th line deleted.
    DeleteLine(usize),
    /// The n-th line written twice.
    DuplicateLine(usize),
    /// The n-th table deleted: its header line and every line to the next header.
    DeleteTable(usize),
    /// A key added after the n-th line that opens a table.
    AddKey(usize, &'static str),
    /// A key added at the start of the n-th inline table.
    AddInlineKey(usize, &'static str),
}

/// Where the literals of a source are (comments skipped).
#[derive(Debug, Default)]
struct Literals {
    /// Byte ranges of the numbers.
    numbers: Vec<(usize, usize)>,
    /// Byte ranges of the strings, quotes included.
    strings: Vec<(usize, usize)>,
    /// Byte offsets just inside each inline table's `{`.
    inline: Vec<usize>,
}

fn literals(src: &str) -> Literals {
    let b = src.as_bytes();
    let Literals {
        mut numbers,
        mut strings,
        mut inline,
    } = Literals::default();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c == b'#' {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if c == b'"' {
            let start = i;
            i += 1;
            while i < b.len() && b[i] != b'"' && b[i] != b'\n' {
                i += if b[i] == b'\\' { 2 } else { 1 };
            }
            i = (i + 1).min(b.len());
            strings.push((start, i));
        } else if c == b'{' {
            inline.push(i + 1);
            i += 1;
        } else if (c.is_ascii_digit()
            || ((c == b'-' || c == b'+') && b.get(i + 1).is_some_and(u8::is_ascii_digit)))
            && (i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_'))
        {
            let start = i;
            i += 1;
            while i < b.len()
                && (b[i].is_ascii_digit()
                    || matches!(b[i], b'.' | b'_' | b'e' | b'E')
                    || (matches!(b[i], b'+' | b'-') && matches!(b[i - 1], b'e' | b'E')))
            {
                i += 1;
            }
            numbers.push((start, i));
        } else {
            i += 1;
        }
    }
    Literals {
        numbers,
        strings,
        inline,
    }
}

fn apply(src: &str, m: &Mutation) -> String {
    let Literals {
        numbers,
        strings,
        inline,
    } = literals(src);
    let replace = |spans: &[(usize, usize)], n: usize, to: &str| {
        if spans.is_empty() {
            return src.to_owned();
        }
        let (a, b) = spans[n % spans.len()];
        format!("{}{to}{}", &src[..a], &src[b..])
    };
    let lines: Vec<&str> = src.split_inclusive('\n').collect();
    match m {
        Mutation::Number(n, to) => replace(&numbers, *n, to),
        Mutation::String(n, to) => replace(&strings, *n, to),
        Mutation::DeleteLine(n) => {
            let k = n % lines.len();
            lines
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != k)
                .map(|(_, l)| *l)
                .collect()
        }
        Mutation::DuplicateLine(n) => {
            let k = n % lines.len();
            let mut out = String::new();
            for (i, l) in lines.iter().enumerate() {
                out.push_str(l);
                if i == k {
                    if !l.ends_with('\n') {
                        out.push('\n');
                    }
                    out.push_str(l);
                }
            }
            out
        }
        Mutation::DeleteTable(n) => {
            let headers = headers(&lines);
            if headers.is_empty() {
                return src.to_owned();
            }
            let k = n % headers.len();
            let end = headers.get(k + 1).copied().unwrap_or(lines.len());
            let (a, b) = (headers[k], end);
            lines
                .iter()
                .enumerate()
                .filter(|(i, _)| !(a..b).contains(i))
                .map(|(_, l)| *l)
                .collect()
        }
        Mutation::AddKey(n, key) => {
            let headers = headers(&lines);
            if headers.is_empty() {
                return src.to_owned();
            }
            let k = headers[n % headers.len()];
            let mut out = String::new();
            for (i, l) in lines.iter().enumerate() {
                out.push_str(l);
                if i == k {
                    out.push_str(key);
                    out.push('\n');
                }
            }
            out
        }
        Mutation::AddInlineKey(n, key) => {
            if inline.is_empty() {
                return src.to_owned();
            }
            let at = inline[n % inline.len()];
            format!("{} {key},{}", &src[..at], &src[at..])
        }
    }
}

/// Indices of the lines that open a table (`[…]`, `[[…]]`).
fn headers(lines: &[&str]) -> Vec<usize> {
    lines
        .iter()
        .enumerate()
        .filter(|(_, l)| l.starts_with('['))
        .map(|(i, _)| i)
        .collect()
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        6 => (any::<usize>(), prop::sample::select(NUMBERS)).prop_map(|(n, t)| Mutation::Number(n, t)),
        2 => (any::<usize>(), prop::sample::select(STRINGS)).prop_map(|(n, t)| Mutation::String(n, t)),
        2 => any::<usize>().prop_map(Mutation::DeleteLine),
        1 => any::<usize>().prop_map(Mutation::DuplicateLine),
        1 => any::<usize>().prop_map(Mutation::DeleteTable),
        1 => (any::<usize>(), prop::sample::select(KEYS)).prop_map(|(n, k)| Mutation::AddKey(n, k)),
        1 => (any::<usize>(), prop::sample::select(KEYS)).prop_map(|(n, k)| Mutation::AddInlineKey(n, k)),
    ]
}

/// The first line of `new` that differs from `old`'s: its number and text.
fn first_change(old: &str, new: &str) -> (usize, String) {
    let mut a = old.lines();
    for (i, line) in new.lines().enumerate() {
        if a.next() != Some(line) {
            return (i + 1, line.to_owned());
        }
    }
    (new.lines().count() + 1, String::new())
}

/// `text` is one line starting `fuzz.toml:LINE:COLUMN: ` with LINE, COLUMN ≥ 1,
/// and has no control character.
fn located(text: &str) -> Result<(), String> {
    located_in(text, ORIGIN)
}

/// `text` is one line starting `FILE:LINE:COLUMN: ` with LINE, COLUMN ≥ 1,
/// and has no control character.
fn located_in(text: &str, file: &str) -> Result<(), String> {
    let ok = !text.chars().any(char::is_control)
        && text
            .strip_prefix(file)
            .and_then(|r| r.strip_prefix(':'))
            .and_then(|r| {
                let mut parts = r.splitn(3, ':');
                let line: usize = parts.next()?.parse().ok()?;
                let column: usize = parts.next()?.parse().ok()?;
                let rest = parts.next()?;
                (line >= 1 && column >= 1 && rest.starts_with(' ')).then_some(())
            })
            .is_some();
    if ok {
        Ok(())
    } else {
        Err(format!("not one line at {file}:LINE:COLUMN: {text:?}"))
    }
}

/// How a source that breaks no other property ended.
#[derive(Debug, Clone, PartialEq)]
enum Outcome {
    /// Refused by the parser or the builder, or its run stopped with an error.
    Refused,
    /// Ran to its end with a sane summary.
    Sane,
    /// Ran to its end `Ok` with an absurd summary (what): a divergence that
    /// nothing stopped.
    Absurd(String),
}

/// Parses, builds and briefly runs `src`; `Err` says which property failed
/// (an absurd summary is left to the caller: [`Outcome::Absurd`]).
fn check(src: &str) -> Result<Outcome, String> {
    let scenario = match Scenario::parse(src, ORIGIN, None) {
        Ok(s) => s,
        Err(e) => return located(&e.to_string()).map(|()| Outcome::Refused),
    };
    let run = match scenario.build(&Overrides::default()) {
        Ok(r) => r,
        Err(e) => return located(&e.to_string()).map(|()| Outcome::Refused),
    };
    for w in &run.warnings {
        located(w).map_err(|e| format!("warning: {e}"))?;
    }
    // The fleet's settings: refused or accepted, never a panic.
    if let Err(e) = scenario.fleet() {
        located(&e.to_string())?;
    }
    let config = run.plan.config();
    let duration = config.duration.min(MAX_DURATION).min(MAX_STEPS * config.dt);
    let run = scenario
        .build(&Overrides {
            duration: Some(duration),
            ..Overrides::default()
        })
        .map_err(|e| format!("built, then refused with --duration {duration}: {e}"))?;
    let mut summary = Summary::new(run.plan.agents().len(), Summary::SETTLE_TOLERANCE);
    let mut sim = run.simulation();
    if sim.run(&mut summary).is_err() {
        // A run stopped with a reason (a state no longer finite, a divergence).
        return Ok(Outcome::Refused);
    }
    for a in summary.agents(run.plan.agents()) {
        let pose = [a.final_pose.x, a.final_pose.y, a.final_pose.theta];
        let sane = |v: f64, bound: f64| v.is_finite() && v.abs() < bound;
        if !(sane(a.final_error, SANE_ERROR)
            && sane(a.rms_error, SANE_ERROR)
            && sane(a.peak_torque, SANE_TORQUE)
            && pose.iter().all(|v| v.is_finite()))
        {
            return Ok(Outcome::Absurd(format!(
                "the run ended Ok with an absurd summary for agent {} after {} s: final error {} m, RMS {} m, peak torque {} N m, final pose {pose:?}",
                a.agent,
                sim.time(),
                a.final_error,
                a.rms_error,
                a.peak_torque
            )));
        }
    }
    Ok(Outcome::Sane)
}

/// [`check`], with a panic turned into its message.
fn check_no_panic(src: &str) -> Result<Outcome, String> {
    catch_unwind(AssertUnwindSafe(|| check(src))).unwrap_or_else(|p| {
        let what = p
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| (*s).to_owned()))
            .unwrap_or_default();
        Err(format!("panicked: {what}"))
    })
}

#[test]
fn every_builtin_passes_unmutated() {
    for (name, src) in scenario::builtin() {
        let outcome = check_no_panic(src).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(outcome, Outcome::Sane, "{name}");
    }
}

/// Every single mutation of every built-in: each number replaced by each of
/// [`NUMBERS`], each string by each of [`STRINGS`], each line deleted and
/// written twice, each table deleted, each of [`KEYS`] added to each table
/// and inline table. About 19 000 checks, 8 s in the test profile.
#[test]
fn every_single_mutation_of_every_builtin() {
    let mut failures = Vec::new();
    let mut diverging = Vec::new();
    let mut count = 0;
    for (name, src) in scenario::builtin() {
        let Literals {
            numbers,
            strings,
            inline,
        } = literals(src);
        let lines = src.split_inclusive('\n').count();
        let headers = src.lines().filter(|l| l.starts_with('[')).count();
        let mut mutations = Vec::new();
        for k in 0..numbers.len() {
            mutations.extend(NUMBERS.iter().map(|t| Mutation::Number(k, t)));
        }
        for k in 0..strings.len() {
            mutations.extend(STRINGS.iter().map(|t| Mutation::String(k, t)));
        }
        for k in 0..lines {
            mutations.push(Mutation::DeleteLine(k));
            mutations.push(Mutation::DuplicateLine(k));
        }
        for k in 0..headers {
            mutations.push(Mutation::DeleteTable(k));
            mutations.extend(KEYS.iter().map(|key| Mutation::AddKey(k, key)));
        }
        for k in 0..inline.len() {
            mutations.extend(KEYS.iter().map(|key| Mutation::AddInlineKey(k, key)));
        }
        for m in &mutations {
            count += 1;
            let text = apply(src, m);
            let (line, changed) = first_change(src, &text);
            let failure = match check_no_panic(&text) {
                Err(e) => e,
                Ok(Outcome::Absurd(e)) => {
                    diverging.push(format!("{name} line {line}: `{changed}`"));
                    e
                }
                Ok(_) => continue,
            };
            failures.push(format!(
                "{name} with {m:?} (line {line}: `{changed}`): {failure}"
            ));
        }
    }
    eprintln!(
        "{count} single mutations checked; {} ran Ok to an absurd summary:\n{}",
        diverging.len(),
        diverging.join("\n")
    );
    assert!(
        failures.is_empty(),
        "{} of {count} failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

proptest! {
    // 4000 cases of one to three mutations: about 1.5 s in the test profile
    // (100 000 cases, 25 s, found nothing more when this test was written).
    #![proptest_config(ProptestConfig::with_cases(4000))]

    #[test]
    fn mutated_builtins_are_refused_with_a_place_or_run_sanely(
        which in any::<prop::sample::Index>(),
        mutations in prop::collection::vec(mutation(), 1..=3),
    ) {
        let builtins = scenario::builtin();
        let (name, src) = builtins[which.index(builtins.len())];
        let mut text = src.to_owned();
        for m in &mutations {
            text = apply(&text, m);
        }
        let failure = match check_no_panic(&text) {
            Err(e) => Some(e),
            Ok(Outcome::Absurd(e)) => Some(e),
            Ok(_) => None,
        };
        if let Some(e) = failure {
            prop_assert!(false, "{name} with {mutations:?}: {e}\n--- source ---\n{text}");
        }
    }
}

/// A short scenario around a waypoint reference: `reference` is the body of
/// its `[reference.waypoints]` table.
fn waypoint_scenario(reference: &str) -> String {
    format!(
        "[sim]\nduration = 0.5\ndt = 0.01\n\n[reference.waypoints]\n{reference}\n[[agents]]\nstart = {{ x = -1.0, y = 0.0, theta = 0.0 }}\nleader = \"reference\"\noffset = {{ x = 0.5, y = 0.0 }}\n"
    )
}

/// `rows` (cell texts `t, x, y`) as TOML `points`, one row a line.
fn toml_points(rows: &[[String; 3]]) -> String {
    let mut s = String::from("points = [\n");
    for r in rows {
        s.push_str(&format!("  [{}, {}, {}],\n", r[0], r[1], r[2]));
    }
    s.push_str("]\n");
    s
}

/// `rows` as a waypoint CSV file.
fn csv_points(rows: &[[String; 3]]) -> String {
    let mut s = String::from("t,x,y\n");
    for r in rows {
        s.push_str(&r.join(","));
        s.push('\n');
    }
    s
}

/// What a waypoint table's mutation does.
#[derive(Debug, Clone)]
enum TableMutation {
    /// Row n's time set to the previous row's plus this much (0: equal).
    Collapse(usize, f64),
    /// Row n moved this far in x and y, m.
    Jump(usize, f64),
    /// Row n's cell (0: t, 1: x, 2: y) replaced by this text.
    Cell(usize, usize, &'static str),
    /// Rows n and n + 1 swapped.
    Swap(usize),
    /// Only the first n rows kept (n modulo the rows, so 0 or 1 at times).
    Truncate(usize),
}

/// What a waypoint cell is replaced by: NaN and infinity spelled every way,
/// numbers at the edge of `f64`, strings and nothing.
const CELLS: &[&str] = &[
    "nan",
    "+nan",
    "-nan",
    "NaN",
    "inf",
    "-inf",
    "\"nan\"",
    "\"1\"",
    "",
    "1e309",
    "1.7976931348623157e308",
    "-1e300",
    "5e-324",
    "-0.0",
];

fn table_mutation() -> impl Strategy<Value = TableMutation> {
    prop_oneof![
        (
            any::<usize>(),
            prop::sample::select(&[0.0, 1e-12, 1e-9, 5e-7, 1e-6][..])
        )
            .prop_map(|(n, e)| TableMutation::Collapse(n, e)),
        (
            any::<usize>(),
            prop::sample::select(&[10.0, 1e3, 1e6, 1e9, 1e300, -1e300][..])
        )
            .prop_map(|(n, d)| TableMutation::Jump(n, d)),
        (any::<usize>(), 0..3usize, prop::sample::select(CELLS))
            .prop_map(|(n, c, t)| TableMutation::Cell(n, c, t)),
        any::<usize>().prop_map(TableMutation::Swap),
        any::<usize>().prop_map(TableMutation::Truncate),
    ]
}

fn mutate_table(rows: &mut Vec<[String; 3]>, m: &TableMutation) {
    let n = rows.len();
    if n == 0 {
        return;
    }
    match *m {
        TableMutation::Collapse(k, eps) => {
            let k = 1 + k % n.saturating_sub(1).max(1);
            if let (Some(prev), true) = (rows[k - 1][0].parse::<f64>().ok(), k < n) {
                rows[k][0] = format!("{:?}", prev + eps);
            }
        }
        TableMutation::Jump(k, d) => {
            let row = &mut rows[k % n];
            for c in [1, 2] {
                if let Ok(v) = row[c].parse::<f64>() {
                    row[c] = format!("{:?}", v + d);
                }
            }
        }
        TableMutation::Cell(k, c, text) => rows[k % n][c] = text.to_owned(),
        TableMutation::Swap(k) => {
            if n >= 2 {
                let k = k % (n - 1);
                rows.swap(k, k + 1);
            }
        }
        TableMutation::Truncate(k) => rows.truncate(k % (n + 1)),
    }
}

/// A valid waypoint table: 2 to 8 rows, 0.5 to 2 s apart, each step at
/// most 15 % of the largest speed on average (the spline's peak between two
/// waypoints is about twice their average speed, more where the path turns).
fn waypoint_table() -> impl Strategy<Value = Vec<[String; 3]>> {
    (
        -100.0..100.0f64,
        (-1e3..1e3f64, -1e3..1e3f64),
        prop::collection::vec(
            (0.5..2.0f64, -1.0..1.0f64, -1.0..1.0f64, 0.0..0.15f64),
            1..8,
        ),
    )
        .prop_map(|(t0, (x0, y0), steps)| {
            let mut p = [t0, x0, y0];
            let mut rows = vec![p.map(|v| format!("{v:?}"))];
            for (gap, dx, dy, f) in steps {
                let norm = dx.hypot(dy).max(1e-9);
                let d = f * Waypoints::MAX_SPEED * gap;
                p = [p[0] + gap, p[1] + d * dx / norm, p[2] + d * dy / norm];
                rows.push(p.map(|v| format!("{v:?}")));
            }
            rows
        })
}

/// The reference's value and derivatives 1–4 are finite before, at, between
/// and after its waypoints.
fn finite_everywhere(r: &Reference) -> Result<(), String> {
    let Reference::Waypoints(w) = r else {
        return Err(format!("not a waypoint reference: {r:?}"));
    };
    let times: Vec<f64> = w.points().iter().map(|p| p[0]).collect();
    let mut at = vec![times[0] - 1.0, times[times.len() - 1] + 1.0];
    for pair in times.windows(2) {
        at.extend([0.0, 0.01, 0.3, 0.5, 0.77, 0.99].map(|s| pair[0] + s * (pair[1] - pair[0])));
    }
    for t in at {
        let j = r.eval(t, Order::Four);
        let all = [j.p, j.dp, j.ddp, j.d3p, j.d4p];
        if !all.iter().flatten().all(|v| v.is_finite()) {
            return Err(format!("the reference at t = {t} s is not finite: {j:?}"));
        }
        // The spline's speed is checked at other times: allow for what
        // happens between them.
        if j.speed() > 1.5 * Waypoints::MAX_SPEED {
            return Err(format!(
                "the reference at t = {t} s is absurdly fast: {j:?}"
            ));
        }
    }
    Ok(())
}

/// Builds the waypoint scenario `src` (its files in `dir`): refused at a
/// place (`fuzz.toml` or, for `csv`, the CSV file), or its reference, finite
/// everywhere. Never a panic.
fn waypoints_refused_or_finite(
    src: &str,
    dir: Option<&Path>,
    csv: Option<&str>,
) -> Result<Option<Vec<[f64; 3]>>, String> {
    let built = catch_unwind(AssertUnwindSafe(|| {
        Scenario::parse(src, ORIGIN, dir).and_then(|s| s.build(&Overrides::default()))
    }))
    .map_err(|_| "panicked".to_owned())?;
    match built {
        Err(e) => {
            let text = e.to_string();
            match csv {
                Some(file) if text.starts_with(file) => located_in(&text, file),
                _ => located(&text),
            }
            .map(|()| None)
        }
        Ok(run) => {
            finite_everywhere(run.plan.reference())?;
            let Reference::Waypoints(w) = run.plan.reference() else {
                unreachable!("checked by finite_everywhere")
            };
            Ok(Some(w.points().to_vec()))
        }
    }
}

/// The wrong answers a new user met, each now refused at its place.
#[test]
fn a_new_users_bad_waypoints_and_safety_are_refused_at_their_place() {
    let points = |rows: &str| waypoint_scenario(&format!("points = [{rows}]\n"));
    let cases = [
        // 1e-9 s apart: a reference at 1e9 m/s.
        (
            points("[0.0, 0.0, 0.0], [1e-9, 1.0, 0.0], [2.0, 2.0, 0.0]"),
            "reference.waypoints.points[2]: waypoint 2 (1-based) at t = 1e-9 s is only 1e-9 s after waypoint 1 at t = 0 s",
        ),
        // 1 km in 1 s.
        (
            points("[0.0, 0.0, 0.0], [1.0, 600.0, 800.0]"),
            "reference.waypoints.points[2]: waypoints 1 and 2 (1-based; t = 0 s and t = 1 s) are 1000 m apart: an average speed of 1000 m/s",
        ),
        (
            points("[0.0, 0.0, 0.0], [1.0, nan, 0.0]"),
            "reference.waypoints.points[2][2]: waypoint 2 (1-based): its x = NaN is not a finite number",
        ),
        // A fourth number in a waypoint was dropped (so was a third in a
        // lemniscate's centre): refused, in any row.
        (
            points("[0.0, 0.0, 0.0, 5.0], [1.0, 1.0, 0.0]"),
            "reference.waypoints.points[1]: invalid length 4, expected an array of length 3",
        ),
        (
            points("[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [2.0, 1.0, 1.0, 0.0, 0.0]"),
            "reference.waypoints.points[3]: invalid length 5, expected an array of length 3",
        ),
        (
            waypoint_scenario("points = [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]]\n").replace(
                "[reference.waypoints]\npoints = [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]]",
                "[reference.lemniscate]\na = 1.0\nc = 0.2\ncenter = [1.0, 2.0, 3.0]",
            ),
            "reference.lemniscate.center: invalid length 3, expected an array of length 2",
        ),
        // An agent's safety without [safety].
        (
            points("[0.0, 0.0, 0.0], [10.0, 1.0, 0.0]")
                .replace("leader = ", "safety = { gain = 2.0 }\nleader = "),
            "agents[1].safety: an agent's safety settings refine the [safety] section, and there is none",
        ),
    ];
    // A fix latency of any size is refused at its plausible range (it sized
    // an allocation first: 1e9 s aborted the process).
    let fix_study = Scenario::builtin("fix-study").unwrap().source().to_owned();
    let cases = cases
        .into_iter()
        .chain(["1e9", "1e15", "1e300"].map(|latency| {
            (
                fix_study.replace(
                    "every_steps = 100",
                    &format!("every_steps = 100\nlatency = {latency}"),
                ),
                "fixes.latency: ",
            )
        }));
    for (src, want) in cases {
        let e = Scenario::parse(&src, ORIGIN, None)
            .and_then(|s| s.build(&Overrides::default()).map(|_| ()))
            .unwrap_err()
            .to_string();
        located(&e).unwrap();
        assert!(e.contains(want), "{e}\n--- wanted ---\n{want}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// A valid waypoint table mutated one to three times, as TOML points and
    /// as a CSV file: refused at a place, or a finite reference — the same
    /// from both.
    #[test]
    fn mutated_waypoint_tables_are_refused_at_a_place_or_finite(
        table in waypoint_table(),
        mutations in prop::collection::vec(table_mutation(), 0..=3),
    ) {
        let mut rows = table;
        for m in &mutations {
            mutate_table(&mut rows, m);
        }
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("w.csv");
        std::fs::write(&csv, csv_points(&rows)).unwrap();
        let shown = csv.display().to_string();
        let from_toml = waypoints_refused_or_finite(&waypoint_scenario(&toml_points(&rows)), None, None);
        let from_csv = waypoints_refused_or_finite(
            &waypoint_scenario("file = \"w.csv\"\n"),
            Some(dir.path()),
            Some(&shown),
        );
        let context = format!("{mutations:?}\n--- rows ---\n{rows:?}");
        let from_toml = from_toml.map_err(|e| TestCaseError::fail(format!("TOML: {e}\n{context}")))?;
        let from_csv = from_csv.map_err(|e| TestCaseError::fail(format!("CSV: {e}\n{context}")))?;
        if let (Some(a), Some(b)) = (&from_toml, &from_csv) {
            prop_assert_eq!(a, b, "{}", context);
        }
        if mutations.is_empty() {
            prop_assert!(from_toml.is_some() && from_csv.is_some(), "a valid table is refused: {}", context);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Two robots starting closer than the safety radius (or a robot near
    /// an obstacle): refused at the agent's `start` with the distance, in
    /// m, then why. It read `start = 1.39: m from agent 1's point …`.
    #[test]
    fn robots_starting_inside_the_safety_radius_are_refused_with_the_distance(
        gap in 0.001_f64..5.0,
        more in 0.001_f64..10.0,
        obstacle in any::<bool>(),
    ) {
        let radius = gap + more;
        let second = if obstacle {
            format!("[safety]\nradius = {radius}\nobstacles = [{{ x = {}, y = 0.0, r = 0.5 }}]\n", 0.05 + gap + 0.5)
        } else {
            format!("[[agents]]\nstart = {{ x = {}, y = 0.0, theta = 0.0 }}\nleader = \"reference\"\noffset = {{ x = 0.5, y = 0.0 }}\n\n[safety]\nradius = {radius}\n", gap)
        };
        let src = format!(
            "[sim]\nduration = 0.1\ndt = 0.01\n\n[reference.line]\nspeed = 0.3\nstart = {{ x = 0.0, y = 0.0, theta = 0.0 }}\n\n[[agents]]\nstart = {{ x = 0.0, y = 0.0, theta = 0.0 }}\nleader = \"reference\"\noffset = {{ x = 0.5, y = 0.0 }}\n\n{second}"
        );
        let e = Scenario::parse(&src, ORIGIN, None)
            .unwrap()
            .build(&Overrides::default())
            .unwrap_err()
            .to_string();
        located(&e).map_err(TestCaseError::fail)?;
        let (agent, what) = if obstacle { (1, "obstacle 1's edge") } else { (2, "agent 1's point L ahead") };
        let head = format!("agents[{agent}].start: ");
        let rest = e.split_once(&head).map(|(_, r)| r);
        prop_assert!(rest.is_some(), "{}", e);
        let (d, tail) = rest.unwrap().split_once(" m from ").unwrap_or(("", ""));
        let d: f64 = d.parse().map_err(|_| TestCaseError::fail(format!("no distance: {e}")))?;
        prop_assert!((d - gap).abs() < 1e-9 * (1.0 + gap), "{} for a gap of {}", e, gap);
        prop_assert!(tail.starts_with(what), "{}", e);
    }
}

/// Every built-in without its agents (every line from the first
/// `[[agents]]` on, which ends each of them but for sections the agents
/// do not need) is refused at the field `agents`, not under the file's
/// first key (`name.agents`).
#[test]
fn a_scenario_without_agents_is_refused_at_agents() {
    for (name, src) in scenario::builtin() {
        let cut = src.find("\n[[agents]]").unwrap();
        let e = match Scenario::parse(&src[..=cut], ORIGIN, None) {
            Err(e) => e,
            Ok(_) => panic!("{name} without agents parsed"),
        };
        located(&e.to_string()).unwrap();
        assert_eq!(e.field, "agents", "{name}: {e}");
    }
}
