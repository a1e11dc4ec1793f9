//! What `fleet doctor` found: one [`Row`] per check and subject, as a
//! table for people and JSON for scripts.

use serde::Serialize;

/// A check's outcome.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// As it should be.
    Pass,
    /// Not judged: said for information (a hub-placed robot's process that
    /// `fleet up` starts later; a check that does not apply).
    Info,
    /// Works, but near a limit: look at it before a long run.
    Warn,
    /// Wrong: the fleet would misbehave; `fleet doctor` exits 1.
    Fail,
}

impl Status {
    /// Its name in the table.
    pub fn name(self) -> &'static str {
        match self {
            Status::Pass => "pass",
            Status::Info => "info",
            Status::Warn => "warn",
            Status::Fail => "FAIL",
        }
    }
}

/// One finding: a check of one subject.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Row {
    /// Whom it is about: `hub` or `robot-K`.
    pub subject: String,
    /// What was checked (`reachable`, `clock offset`, `odometry`, …).
    pub check: String,
    /// The outcome.
    pub status: Status,
    /// What was measured, short (`20.1 Hz`, `+0.3 ms`).
    pub value: String,
    /// How it was measured, or what to do about it.
    pub detail: String,
}

impl Row {
    /// A row of `subject`'s `check`.
    pub fn new(
        subject: &str,
        check: &str,
        status: Status,
        value: impl Into<String>,
        detail: impl Into<String>,
    ) -> Row {
        Row {
            subject: subject.to_owned(),
            check: check.to_owned(),
            status,
            value: value.into(),
            detail: detail.into(),
        }
    }
}

/// How many rows of each status.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct Counts {
    /// Rows that passed.
    pub pass: usize,
    /// Rows said for information.
    pub info: usize,
    /// Rows that warn.
    pub warn: usize,
    /// Rows that failed.
    pub fail: usize,
}

/// Everything `fleet doctor` found, in the order it prints it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DoctorReport {
    /// The fleet's name.
    pub fleet: String,
    /// This echelon's version.
    pub version: String,
    /// Whether no check failed (warnings pass).
    pub ok: bool,
    /// How many rows of each status.
    pub counts: Counts,
    /// The findings, hub first, then robot by robot.
    pub rows: Vec<Row>,
}

impl DoctorReport {
    /// The report of `rows` for `fleet`.
    pub fn new(fleet: &str, rows: Vec<Row>) -> DoctorReport {
        let count = |s: Status| rows.iter().filter(|r| r.status == s).count();
        let counts = Counts {
            pass: count(Status::Pass),
            info: count(Status::Info),
            warn: count(Status::Warn),
            fail: count(Status::Fail),
        };
        DoctorReport {
            fleet: fleet.to_owned(),
            version: crate::probe::VERSION.to_owned(),
            ok: counts.fail == 0,
            counts,
            rows,
        }
    }

    /// The rows that failed.
    pub fn failed(&self) -> impl Iterator<Item = &Row> {
        self.rows.iter().filter(|r| r.status == Status::Fail)
    }

    /// The table: a header, a line per row (columns padded to their
    /// widest), a summary line.
    pub fn table(&self) -> String {
        let head = ["subject", "check", "status", "value", "detail"];
        let cells: Vec<[&str; 5]> = self
            .rows
            .iter()
            .map(|r| {
                [
                    r.subject.as_str(),
                    r.check.as_str(),
                    r.status.name(),
                    r.value.as_str(),
                    r.detail.as_str(),
                ]
            })
            .collect();
        let mut width = head.map(|h| h.chars().count());
        for row in &cells {
            for (w, c) in width.iter_mut().zip(row) {
                *w = (*w).max(c.chars().count());
            }
        }
        let line = |row: &[&str; 5]| {
            let mut s = String::new();
            for (i, (c, w)) in row.iter().zip(width).enumerate() {
                if i + 1 == row.len() {
                    s.push_str(c);
                } else {
                    s.push_str(c);
                    s.extend(std::iter::repeat_n(' ', w - c.chars().count() + 2));
                }
            }
            s.trim_end().to_owned()
        };
        let mut out = line(&head);
        out.push('\n');
        for row in &cells {
            out.push_str(&line(row));
            out.push('\n');
        }
        let Counts {
            pass,
            info,
            warn,
            fail,
        } = self.counts;
        out.push_str(&format!(
            "fleet `{}`: {pass} pass, {warn} warn, {fail} fail, {info} info\n",
            self.fleet
        ));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_lines_up_and_counts() {
        let report = DoctorReport::new(
            "lab",
            vec![
                Row::new("hub", "reachable", Status::Pass, "tcp/10.0.0.1:7447", "tcp"),
                Row::new("robot-1", "odometry", Status::Fail, "2.0 Hz", "slow"),
                Row::new("robot-1", "clock offset", Status::Warn, "+7.0 ms", ""),
            ],
        );
        assert!(!report.ok);
        let counts = Counts {
            pass: 1,
            info: 0,
            warn: 1,
            fail: 1,
        };
        assert_eq!(report.counts, counts);
        let table = report.table();
        let lines: Vec<&str> = table.lines().collect();
        assert_eq!(lines.len(), 5, "{table}");
        let at = |l: &str| l.find("pass").or(l.find("FAIL")).or(l.find("warn"));
        assert_eq!(at(lines[1]), at(lines[2]), "{table}");
        assert_eq!(at(lines[2]), at(lines[3]), "{table}");
        assert!(lines[4].contains("1 pass, 1 warn, 1 fail"), "{table}");
        assert_eq!(report.failed().count(), 1);
    }
}
