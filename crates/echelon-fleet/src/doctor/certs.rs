//! The secure mode's certificates checked: each identity's certificate in
//! the directory is readable, signed by the directory's CA, named
//! `echelon-<identity>`, valid now and for longer than
//! [`EXPIRY_WARNING_DAYS`], and has its key beside it.

use std::path::Path;

use x509_parser::certificate::X509Certificate;
use x509_parser::pem::Pem;

use super::report::{Row, Status};
use crate::net::{common_name, identity_files};

/// A certificate expiring within this many days is a warning.
pub const EXPIRY_WARNING_DAYS: f64 = 30.0;

/// Whose a certificate is, in the report: `robot-K` for robot K's and base
/// K's, `hub` for the others (and the CA).
fn subject_of(identity: &str) -> String {
    match identity
        .strip_prefix("robot-")
        .or_else(|| identity.strip_prefix("base-"))
    {
        Some(k) => format!("robot-{k}"),
        None => "hub".to_owned(),
    }
}

/// A UNIX time as a date, `YYYY-MM-DD`.
fn date(unix: i64) -> String {
    time::OffsetDateTime::from_unix_timestamp(unix)
        .map_or_else(|_| format!("{unix} s"), |t| t.date().to_string())
}

/// Checks the CA and `identities`' certificates in `dir` at the UNIX time
/// `now` (s): one row each.
pub(super) fn check(dir: &Path, identities: &[String], now: i64) -> Vec<Row> {
    let mut rows = Vec::new();
    let ca_path = dir.join("ca.pem");
    let ca_pem = read_pem(&ca_path);
    let ca = ca_pem.as_ref().map_err(Clone::clone).and_then(|p| {
        p.parse_x509()
            .map_err(|e| format!("{}: not an X.509 certificate: {e}", ca_path.display()))
    });
    match &ca {
        Ok(ca) => rows.push(validity(
            Row::new("hub", "certificate ca", Status::Pass, "", ""),
            ca,
            now,
        )),
        Err(e) => rows.push(Row::new(
            "hub",
            "certificate ca",
            Status::Fail,
            "unreadable",
            format!(
                "{e} (make the certificates with `echelon fleet certs {}`)",
                dir.display()
            ),
        )),
    }
    for id in identities {
        let row = Row::new(
            &subject_of(id),
            &format!("certificate {id}"),
            Status::Pass,
            "",
            "",
        );
        let (cert_path, key_path) = identity_files(dir, id);
        if !cert_path.exists() {
            rows.push(Row {
                status: Status::Warn,
                value: "absent".into(),
                detail: format!(
                    "no {} here: the machine that runs {id} needs it",
                    cert_path.display()
                ),
                ..row
            });
            continue;
        }
        let pem = match read_pem(&cert_path) {
            Ok(p) => p,
            Err(e) => {
                rows.push(fail(row, "unreadable", e));
                continue;
            }
        };
        let cert = match pem.parse_x509() {
            Ok(c) => c,
            Err(e) => {
                let why = format!("{}: not an X.509 certificate: {e}", cert_path.display());
                rows.push(fail(row, "unreadable", why));
                continue;
            }
        };
        let cn = cert
            .subject()
            .iter_common_name()
            .next()
            .and_then(|c| c.as_str().ok())
            .unwrap_or_default()
            .to_owned();
        if cn != common_name(id) {
            let why = format!(
                "{} is {cn:?}'s, not {:?}'s: the access control would refuse it",
                cert_path.display(),
                common_name(id)
            );
            rows.push(fail(row, "wrong name", why));
            continue;
        }
        if let Ok(ca) = &ca
            && cert.verify_signature(Some(ca.public_key())).is_err()
        {
            let why = format!(
                "{} is not signed by {}: certificates from another `fleet certs` run? (make them all at once, and copy the same ca.pem everywhere)",
                cert_path.display(),
                ca_path.display()
            );
            rows.push(fail(row, "another CA", why));
            continue;
        }
        if !key_path.is_file() {
            let why = format!("no {} beside the certificate", key_path.display());
            rows.push(fail(row, "no key", why));
            continue;
        }
        rows.push(validity(row, &cert, now));
    }
    rows
}

fn fail(row: Row, value: &str, detail: String) -> Row {
    Row {
        status: Status::Fail,
        value: value.to_owned(),
        detail,
        ..row
    }
}

/// `row` judged by `cert`'s validity at `now`.
fn validity(row: Row, cert: &X509Certificate<'_>, now: i64) -> Row {
    let v = cert.validity();
    let (from, until) = (v.not_before.timestamp(), v.not_after.timestamp());
    let left = (until - now) as f64 / 86_400.0;
    let (status, value, detail) = if now < from {
        (
            Status::Fail,
            format!("valid from {}", date(from)),
            "not valid yet: is this machine's clock right?".to_owned(),
        )
    } else if now > until {
        (
            Status::Fail,
            format!("expired {}", date(until)),
            "expired: links with it are refused; make new certificates (`echelon fleet certs`)"
                .to_owned(),
        )
    } else if left < EXPIRY_WARNING_DAYS {
        (
            Status::Warn,
            format!("until {}", date(until)),
            format!("expires in {left:.0} days: renew it before it does"),
        )
    } else {
        (
            Status::Pass,
            format!("until {}", date(until)),
            format!("valid since {}", date(from)),
        )
    };
    Row {
        status,
        value,
        detail,
        ..row
    }
}

/// The first PEM block of `path`.
fn read_pem(path: &Path) -> Result<Pem, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    Pem::iter_from_buffer(&bytes)
        .next()
        .ok_or_else(|| format!("{}: no PEM block", path.display()))?
        .map_err(|e| format!("{}: not PEM: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::certs::{CertOptions, generate_with};

    /// Certificates of one robot, robot 1's expiring in `days` days.
    fn rows(days: f64) -> Vec<Row> {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let opts = CertOptions {
            dir: dir.path().to_path_buf(),
            robots: 1,
            hosts: Vec::new(),
        };
        generate_with(&opts, &[("robot-1".to_owned(), days)]).unwrap_or_else(|e| panic!("{e}"));
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs() as i64);
        check(dir.path(), &crate::net::identities(1), now)
    }

    fn status(rows: &[Row], check: &str) -> Status {
        rows.iter()
            .find(|r| r.check == check)
            .map_or_else(|| panic!("no {check}: {rows:?}"), |r| r.status)
    }

    /// Fresh certificates pass; one expired a day ago fails, one expiring
    /// in 10 days warns, in 60 days passes; the others are untouched.
    #[test]
    fn expired_and_expiring_certificates_are_found() {
        let expired = rows(-1.0);
        assert_eq!(status(&expired, "certificate robot-1"), Status::Fail);
        assert_eq!(status(&expired, "certificate ca"), Status::Pass);
        assert_eq!(status(&expired, "certificate base-1"), Status::Pass);
        assert_eq!(status(&expired, "certificate operator"), Status::Pass);
        assert_eq!(expired.len(), 7, "{expired:?}");
        let row = expired.iter().find(|r| r.check == "certificate robot-1");
        assert_eq!(row.map(|r| r.subject.as_str()), Some("robot-1"));
        assert_eq!(status(&rows(10.0), "certificate robot-1"), Status::Warn);
        assert_eq!(status(&rows(60.0), "certificate robot-1"), Status::Pass);
    }

    /// A certificate of another CA, one under another name, a missing key
    /// and a missing certificate are each said.
    #[test]
    fn foreign_misnamed_and_missing_files_are_found() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let make = |d: &Path| {
            crate::certs::generate(&CertOptions {
                dir: d.to_path_buf(),
                robots: 2,
                hosts: Vec::new(),
            })
            .unwrap_or_else(|e| panic!("{e}"))
        };
        let (a, b) = (dir.path().join("a"), dir.path().join("b"));
        make(&a);
        make(&b);
        let copy = |from: &Path, to: &Path| {
            std::fs::copy(from, to).unwrap_or_else(|e| panic!("{e}"));
        };
        copy(&b.join("robot-1.pem"), &a.join("robot-1.pem"));
        copy(&a.join("robot-2.pem"), &a.join("leader.pem"));
        std::fs::remove_file(a.join("base-1-key.pem")).unwrap_or_else(|e| panic!("{e}"));
        std::fs::remove_file(a.join("base-2.pem")).unwrap_or_else(|e| panic!("{e}"));
        let rows = check(&a, &crate::net::identities(2), 1_800_000_000);
        let value = |c: &str| rows.iter().find(|r| r.check == c).map(|r| r.value.clone());
        assert_eq!(value("certificate robot-1").as_deref(), Some("another CA"));
        assert_eq!(value("certificate leader").as_deref(), Some("wrong name"));
        assert_eq!(value("certificate base-1").as_deref(), Some("no key"));
        assert_eq!(value("certificate base-2").as_deref(), Some("absent"));
        assert_eq!(status(&rows, "certificate robot-2"), Status::Pass);
        let none = check(&dir.path().join("none"), &[], 0);
        assert_eq!(status(&none, "certificate ca"), Status::Fail);
    }
}
