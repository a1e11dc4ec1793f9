//! A logged manoeuvre ([`Log`]): read from a run directory or built in memory,
//! and checked before it is fitted.

use std::path::Path;

use super::{IdentifyError, MIN_SAMPLES, Model};

/// A logged manoeuvre of one robot: velocities measured at the sample times
/// and the inputs held from each sample to the next.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Log {
    /// Where it came from (in errors and the summary).
    pub source: String,
    /// The agent number, from 1.
    pub agent: usize,
    /// Sample times, s, increasing.
    pub t: Vec<f64>,
    /// Measured linear speed, m/s.
    pub v: Vec<f64>,
    /// Measured angular speed, rad/s.
    pub omega: Vec<f64>,
    /// Torque inputs `u1` (N), `u2` (N m), if logged.
    pub u: Option<[Vec<f64>; 2]>,
    /// Wheel torques `τr, τl`, N m, if logged (give `l`, `r` with `u`).
    pub tau: Option<[Vec<f64>; 2]>,
    /// Commanded `(v*, ω*)`, if logged.
    pub cmd: Option<[Vec<f64>; 2]>,
    /// The command after the base's speed limits, if logged.
    pub applied: Option<[Vec<f64>; 2]>,
    /// The running integrals at the sample times (a run's `integrals.csv`),
    /// if logged: with them the fit is exact whatever the input did between
    /// samples.
    pub integrals: Option<Integrals>,
    /// What reading the log found worth saying (copied into the warnings).
    pub notes: Vec<String>,
    /// The inputs' own zero-order hold when it is known apart from the
    /// samples (a ROS 2 bag's command messages): the output-error fit then
    /// integrates the model exactly on it, instead of holding the inputs'
    /// per-sample values (`cmd`, `applied`, `u`) over each interval.
    pub hold: Option<Hold>,
    /// The period over which the plant's input was held, s, when the log
    /// says (a run directory's `summary.json`: the controller period, or
    /// `dt` when a safety filter holds each step's command; `None` for a
    /// continuous-time law or an unknown source). A log slower than this
    /// hold, without integrals, cannot know the input between its samples:
    /// holding the sampled values is then not taken as exact
    /// ([`fit`](super)), and the spread of the hold, the backward hold and
    /// the ramp joins each interval.
    pub input_period: Option<f64>,
}

/// Inputs held from each switch time to the next.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Hold {
    /// Switch times, s, on the clock of [`Log::t`], increasing; the first at
    /// or before the first sample.
    pub t: Vec<f64>,
    /// The two inputs' values held from each switch time.
    pub u: [Vec<f64>; 2],
}

/// Running integrals of one agent at the sample times
/// ([`crate::output::INTEGRALS_HEADER`]); only their differences are used.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Integrals {
    /// Distance travelled `∫v dt`, m.
    pub s: Vec<f64>,
    /// Heading, not wrapped (`θ₀ + ∫ω dt`), rad.
    pub theta: Vec<f64>,
    /// `∫ input dt` of the plant's inputs: `u1, u2` (torque) or the applied
    /// `v, ω` command (velocity base).
    pub input: [Vec<f64>; 2],
}

/// How a truncated `integrals.csv` is refused: the start of the reason.
const TRUNCATED: &str =
    "truncated (cut before the run's end, identify does not fit on part of a run)";

/// Why an `integrals.csv` was not attached.
enum Attach {
    /// The file was cut short: a hard error, naming the row.
    Truncated(String),
    /// Anything else: the fit falls back to the sampled inputs, with a note.
    Unusable(String),
}

/// Whether `text`, an `integrals.csv`, was cut mid-write, and where. A
/// complete file ends every row, its last included, with a newline and
/// has as many fields in each as its header
/// ([`crate::output::INTEGRALS_HEADER`]); a file cut before its end has a
/// last line without its newline (or without some of its fields). Rows
/// missing at the end are found against the log's sample times
/// ([`Log::attach_integrals`]); the file itself carries no row count.
pub fn integrals_truncation(text: &str) -> Option<String> {
    if text.is_empty() {
        return Some(format!(
            "{TRUNCATED}: the file is empty, not even its header"
        ));
    }
    let mut lines = text.split_inclusive('\n');
    let header = lines.next().unwrap_or("");
    let fields = header.trim_end().split(',').count();
    if !header.ends_with('\n') {
        return Some(format!(
            "{TRUNCATED}: it ends in its header, without the header's newline"
        ));
    }
    let (mut rows, mut last) = (0usize, None);
    for line in lines {
        rows += 1;
        last = Some(line);
    }
    let Some(last) = last else {
        return Some(format!("{TRUNCATED}: it has no row after its header"));
    };
    let n = last.trim_end().split(',').count();
    if !last.ends_with('\n') {
        Some(format!(
            "{TRUNCATED}: row {rows} (line {}) is cut short, without its newline ({n} of {fields} fields: `{}`)",
            rows + 1,
            last.trim_end()
        ))
    } else if n < fields {
        Some(format!(
            "{TRUNCATED}: row {rows} (line {}) has {n} of {fields} fields: `{}`",
            rows + 1,
            last.trim_end()
        ))
    } else {
        None
    }
}

/// Reads a CSV column set into per-agent series.
pub(super) fn column(header: &csv::StringRecord, name: &str) -> Option<usize> {
    header.iter().position(|h| h.trim() == name)
}

impl Log {
    /// Reads agent `agent`'s rows of `DIR/trajectory.csv` (an `echelon run`
    /// directory), or of the CSV file itself if `path` is a file.
    pub fn read_run(path: &Path, agent: usize) -> Result<Log, IdentifyError> {
        let file = if path.is_dir() {
            path.join(crate::output::TRAJECTORY_FILE)
        } else {
            path.to_path_buf()
        };
        let origin = file.display().to_string();
        let text = std::fs::read_to_string(&file).map_err(|e| IdentifyError::Read {
            file: origin.clone(),
            reason: format!("cannot read: {e}"),
        })?;
        let mut log = Log::parse_csv(&text, &origin, agent)?;
        log.input_period = file
            .parent()
            .and_then(|d| std::fs::read_to_string(d.join(crate::output::SUMMARY_FILE)).ok())
            .and_then(|text| serde_json::from_str::<serde_json::Value>(&text).ok())
            .and_then(|s| {
                let dt = s["dt"].as_f64();
                s["controller_period"]
                    .as_f64()
                    .or_else(|| s.get("safety").and(dt))
            });
        let beside = file.parent().map(|d| d.join(crate::output::INTEGRALS_FILE));
        if let Some(path) = beside.filter(|p| p.is_file()) {
            match std::fs::read_to_string(&path)
                .map_err(|e| Attach::Unusable(e.to_string()))
                .and_then(|text| log.attach(&text))
            {
                Ok(()) => {}
                // A file cut before the run's end: refused, never fitted on
                // the part that is there nor silently replaced.
                Err(Attach::Truncated(reason)) => {
                    return Err(IdentifyError::Read {
                        file: path.display().to_string(),
                        reason,
                    });
                }
                Err(Attach::Unusable(why)) => log.notes.push(format!(
                    "{} not used: {why}; the fit falls back to the sampled inputs",
                    path.display()
                )),
            }
        }
        Ok(log)
    }

    /// Attaches this agent's rows of an `integrals.csv` (header
    /// [`crate::output::INTEGRALS_HEADER`]); they must be at the log's
    /// sample times. A truncated file ([`integrals_truncation`]) is refused
    /// with the row where it was cut.
    pub fn attach_integrals(&mut self, text: &str) -> Result<(), String> {
        self.attach(text).map_err(|e| match e {
            Attach::Truncated(why) | Attach::Unusable(why) => why,
        })
    }

    /// [`Log::attach_integrals`], telling a truncated file from one that
    /// is otherwise unusable.
    fn attach(&mut self, text: &str) -> Result<(), Attach> {
        if let Some(why) = integrals_truncation(text) {
            return Err(Attach::Truncated(why));
        }
        self.attach_rows(text).map_err(|why| {
            if why.starts_with(TRUNCATED) {
                Attach::Truncated(why)
            } else {
                Attach::Unusable(why)
            }
        })
    }

    /// The rows of [`Log::attach_integrals`] once the file is known whole.
    fn attach_rows(&mut self, text: &str) -> Result<(), String> {
        let mut rdr = csv::ReaderBuilder::new().from_reader(text.as_bytes());
        let header = rdr.headers().map_err(|e| e.to_string())?.clone();
        let names = ["t", "agent", "s", "theta", "int_1", "int_2"];
        let idx: Vec<usize> = names
            .iter()
            .map(|c| column(&header, c).ok_or_else(|| format!("no column {c}")))
            .collect::<Result<_, _>>()?;
        let mut cols: [Vec<f64>; 5] = Default::default();
        // The file's last row: its time and agent (frames are logged in
        // time order, each agent in turn).
        let mut last_row: Option<(f64, f64)> = None;
        for (line, rec) in rdr.records().enumerate() {
            let rec = rec.map_err(|e| format!("line {}: {e}", line + 2))?;
            let num = |k: usize| -> Result<f64, String> {
                let cell = rec.get(idx[k]).unwrap_or("");
                cell.trim()
                    .parse::<f64>()
                    .map_err(|_| format!("line {}: {} = `{cell}`", line + 2, names[k]))
            };
            last_row = Some((num(0)?, num(1)?));
            if num(1)? != self.agent as f64 {
                continue;
            }
            for (k, c) in [0, 2, 3, 4, 5].into_iter().zip(cols.iter_mut()) {
                c.push(num(k)?);
            }
        }
        let [t, s, theta, i1, i2] = cols;
        // No row of this agent, and the file ends before its first one
        // would come (at its first sample time, after the agents before
        // it): cut there.
        if t.is_empty()
            && let (Some((t_last, a_last)), Some(&first)) = (last_row, self.t.first())
            && (t_last < first - 1e-9
                || ((t_last - first).abs() <= 1e-9 && a_last < self.agent as f64))
        {
            return Err(format!(
                "{TRUNCATED}: the file ends at t = {t_last} s (agent {a_last}'s row), before agent {}'s first row (t = {first} s)",
                self.agent
            ));
        }
        if !t.is_empty()
            && t.len() < self.t.len()
            && t.iter().zip(&self.t).all(|(a, b)| (a - b).abs() <= 1e-9)
        {
            // The rows stop early but agree up to there: rows missing at the
            // end, which a written file never has (every frame logs every
            // agent, and the file is renamed into place only when complete).
            return Err(format!(
                "{TRUNCATED}: agent {}'s rows stop at t = {} s, its row {} of the {} the log's sample times (to t = {} s) ask for",
                self.agent,
                t[t.len() - 1],
                t.len(),
                self.t.len(),
                self.t[self.t.len() - 1],
            ));
        }
        if t.len() != self.t.len() || t.iter().zip(&self.t).any(|(a, b)| (a - b).abs() > 1e-9) {
            return Err(format!(
                "its {} rows of agent {} are not at the log's {} sample times",
                t.len(),
                self.agent,
                self.t.len()
            ));
        }
        if [&s, &theta, &i1, &i2]
            .iter()
            .any(|c| c.iter().any(|x| !x.is_finite()))
        {
            return Err("non-finite values".to_owned());
        }
        self.integrals = Some(Integrals {
            s,
            theta,
            input: [i1, i2],
        });
        Ok(())
    }

    /// Parses a `trajectory.csv` (header with `t, agent, v, omega` and some of
    /// `u1, u2, tau_r, tau_l, v_cmd, omega_cmd, v_applied, omega_applied`).
    pub fn parse_csv(text: &str, origin: &str, agent: usize) -> Result<Log, IdentifyError> {
        let read_err = |reason: String| IdentifyError::Read {
            file: origin.to_owned(),
            reason,
        };
        let mut rdr = csv::ReaderBuilder::new().from_reader(text.as_bytes());
        let header = rdr
            .headers()
            .map_err(|e| read_err(format!("not a CSV file: {e}")))?
            .clone();
        let base = ["t", "agent", "v", "omega"];
        let missing: Vec<&str> = base
            .iter()
            .copied()
            .filter(|c| column(&header, c).is_none())
            .collect();
        if !missing.is_empty() {
            return Err(read_err(format!(
                "missing column(s) {} (a trajectory.csv has t, agent, v, omega)",
                missing.join(", ")
            )));
        }
        let idx = |c: &str| column(&header, c);
        let pair = |a: &str, b: &str| idx(a).zip(idx(b));
        let (it, ia, iv, iw) = (idx("t"), idx("agent"), idx("v"), idx("omega"));
        let groups = [
            pair("u1", "u2"),
            pair("tau_r", "tau_l"),
            pair("v_cmd", "omega_cmd"),
            pair("v_applied", "omega_applied"),
        ];
        let mut log = Log {
            source: origin.to_owned(),
            agent,
            ..Log::default()
        };
        let mut cols: [[Vec<f64>; 2]; 4] = Default::default();
        let mut agents = std::collections::BTreeSet::new();
        for (line, rec) in rdr.records().enumerate() {
            let rec = rec.map_err(|e| read_err(format!("line {}: {e}", line + 2)))?;
            let num = |i: Option<usize>, name: &str| -> Result<f64, IdentifyError> {
                let cell = i.and_then(|i| rec.get(i)).unwrap_or("");
                cell.trim().parse::<f64>().map_err(|_| {
                    read_err(format!(
                        "line {}: {name} = `{cell}` is not a number",
                        line + 2
                    ))
                })
            };
            let a = num(ia, "agent")?;
            agents.insert(a as i64);
            if a != agent as f64 {
                continue;
            }
            log.t.push(num(it, "t")?);
            log.v.push(num(iv, "v")?);
            log.omega.push(num(iw, "omega")?);
            for (g, cols) in groups.iter().zip(cols.iter_mut()) {
                if let Some((i0, i1)) = g {
                    cols[0].push(num(Some(*i0), &header[*i0])?);
                    cols[1].push(num(Some(*i1), &header[*i1])?);
                }
            }
        }
        if log.t.is_empty() {
            let present: Vec<String> = agents.iter().map(i64::to_string).collect();
            return Err(IdentifyError::NoAgent {
                file: origin.to_owned(),
                agent,
                present: if present.is_empty() {
                    "none".to_owned()
                } else {
                    present.join(", ")
                },
            });
        }
        let [u, tau, cmd, applied] = cols;
        // A group is present if logged and not all NaN (a torque agent's
        // velocity cells and a velocity agent's torque cells are NaN).
        let keep = |g: Option<(usize, usize)>, c: [Vec<f64>; 2]| {
            (g.is_some() && !c[0].iter().all(|x| x.is_nan())).then_some(c)
        };
        log.u = keep(groups[0], u);
        log.tau = keep(groups[1], tau);
        log.cmd = keep(groups[2], cmd);
        log.applied = keep(groups[3], applied);
        Ok(log)
    }

    /// The model this log can serve: torque if it has `u1, u2`, velocity if
    /// it has the applied command, `None` if neither.
    pub fn detect(&self) -> Option<Model> {
        if self.u.is_some() {
            Some(Model::Torque)
        } else if self.applied.is_some() || self.cmd.is_some() {
            Some(Model::Velocity)
        } else {
            None
        }
    }

    pub(super) fn check(&self, model: Model) -> Result<(), IdentifyError> {
        let file = || self.source.clone();
        let (names, inputs) = match model {
            Model::Torque => (["u1", "u2"], self.u.as_ref()),
            Model::Velocity => (
                ["v_applied", "omega_applied"],
                self.applied.as_ref().or(self.cmd.as_ref()),
            ),
        };
        let needed = match model {
            Model::Torque => "t, agent, v, omega, u1, u2",
            Model::Velocity => {
                "t, agent, v, omega and v_applied, omega_applied (or v_cmd, omega_cmd)"
            }
        };
        let Some(inputs) = inputs else {
            return Err(IdentifyError::MissingColumns {
                file: file(),
                columns: names.join(", "),
                model,
                needed: needed.to_owned(),
            });
        };
        let n = self.t.len();
        if n < MIN_SAMPLES {
            return Err(IdentifyError::TooShort {
                file: file(),
                agent: self.agent,
                samples: n,
                min: MIN_SAMPLES,
            });
        }
        let series: [(&'static str, &[f64]); 5] = [
            ("t", &self.t),
            ("v", &self.v),
            ("omega", &self.omega),
            (
                if model == Model::Torque {
                    "u1"
                } else {
                    "v_applied"
                },
                &inputs[0],
            ),
            (
                if model == Model::Torque {
                    "u2"
                } else {
                    "omega_applied"
                },
                &inputs[1],
            ),
        ];
        for (column, s) in series {
            if let Some(i) = s.iter().position(|x| !x.is_finite()) {
                return Err(IdentifyError::NonFinite {
                    file: file(),
                    column,
                    value: s[i],
                    t: self.t[i],
                    agent: self.agent,
                });
            }
        }
        if let Some(i) = self.t.windows(2).position(|w| w[1] <= w[0]) {
            return Err(IdentifyError::Time {
                file: file(),
                t: self.t[i + 1],
                agent: self.agent,
            });
        }
        if let Some(h) = &self.hold {
            h.check(self.t[0]).map_err(|why| IdentifyError::Read {
                file: file(),
                reason: format!("the command hold (Log::hold) {why}"),
            })?;
        }
        Ok(())
    }
}

impl Hold {
    /// Why this hold cannot drive a fit of a log starting at `t0`: no
    /// switch, values not one per switch, a value or time not finite, times
    /// that do not increase, or a first switch after `t0`.
    fn check(&self, t0: f64) -> Result<(), String> {
        let n = self.t.len();
        if n == 0 {
            return Err("has no switch".to_owned());
        }
        if self.u.iter().any(|u| u.len() != n) {
            return Err(format!(
                "has {n} switch times but {} and {} values",
                self.u[0].len(),
                self.u[1].len()
            ));
        }
        let finite = |x: &f64| x.is_finite();
        if let Some(i) =
            (0..n).find(|&i| !(finite(&self.t[i]) && self.u.iter().all(|u| finite(&u[i]))))
        {
            return Err(format!("has a value that is not finite at switch {i}"));
        }
        if let Some(i) = self.t.windows(2).position(|w| w[1] <= w[0]) {
            return Err(format!(
                "switch times do not increase at t = {} s",
                self.t[i + 1]
            ));
        }
        if self.t[0] > t0 {
            return Err(format!(
                "starts at t = {} s, after the first sample (t = {t0} s): the input before it is unknown",
                self.t[0]
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod truncation_tests {
    use super::*;
    use proptest::prelude::*;

    /// A complete `integrals.csv` of two agents at `n` sample times, as a
    /// run writes it (`CsvWriter`: every row ends with its newline).
    fn complete(n: usize) -> String {
        let mut text = format!("{}\n", crate::output::INTEGRALS_HEADER);
        for k in 0..n {
            for agent in 1..=2 {
                let t = k as f64 * 0.01;
                text.push_str(&format!(
                    "{t},{agent},{},{},{},{}\n",
                    0.123456 * t,
                    1.5 + 0.25 * t,
                    -3.0625 * t,
                    7.5 * t
                ));
            }
        }
        text
    }

    /// Agent `agent`'s log at the `n` sample times of [`complete`].
    fn log(agent: usize, n: usize) -> Log {
        Log {
            agent,
            t: (0..n).map(|k| k as f64 * 0.01).collect(),
            ..Log::default()
        }
    }

    #[test]
    fn a_complete_file_attaches() {
        let mut l = log(2, 60);
        l.attach_integrals(&complete(60)).unwrap();
        assert_eq!(l.integrals.unwrap().s.len(), 60);
    }

    #[test]
    fn a_partial_last_line_names_its_row() {
        let text = complete(60);
        // The last row, `0.59,2,…`, cut inside its third field.
        let cut = &text[..text.len() - 20];
        let why = integrals_truncation(cut).unwrap();
        assert!(why.starts_with(TRUNCATED), "{why}");
        assert!(why.contains("row 120 (line 121)"), "{why}");
        let mut l = log(1, 60);
        let e = l.attach(cut).unwrap_err();
        assert!(matches!(e, Attach::Truncated(_)));
    }

    proptest! {
        /// Whatever byte a complete file is cut at, the last agent's
        /// integrals are refused as truncated, never attached on the part
        /// that is there nor taken as merely unusable (which would let the
        /// fit go on with the sampled inputs): a partial last line by its
        /// missing newline or fields, whole rows missing at the end by the
        /// log's sample times.
        #[test]
        fn a_file_cut_anywhere_is_refused_as_truncated(n in 1usize..40, at in 0.0f64..1.0) {
            let text = complete(n);
            let k = ((text.len() as f64 * at) as usize).min(text.len() - 1);
            let mut l = log(2, n);
            match l.attach(&text[..k]) {
                Err(Attach::Truncated(why)) => prop_assert!(why.starts_with(TRUNCATED)),
                Err(Attach::Unusable(why)) => prop_assert!(false, "cut at {k}: only unusable: {why}"),
                Ok(()) => prop_assert!(false, "cut at {k}: attached"),
            }
            prop_assert!(l.integrals.is_none());
        }
    }
}
