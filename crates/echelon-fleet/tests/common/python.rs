//! The Python helpers under `scripts/ros2/`, as the ROS 2 test binaries run
//! them.

#![allow(dead_code)]

use std::io::Write;
use std::path::PathBuf;
use std::process::{Command, Stdio};

use serde_json::Value;

/// The interpreter the helpers run with: `ECHELON_PYTHON`, else `python3`.
pub(crate) fn python() -> String {
    std::env::var("ECHELON_PYTHON").unwrap_or_else(|_| "python3".to_owned())
}

/// `scripts/ros2/<name>`.
pub(crate) fn script(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../scripts/ros2")
        .join(name)
}

/// The helpers as one test binary runs them: with an interpreter, and
/// what to install when they cannot run.
pub(crate) struct Helpers {
    /// The interpreter.
    pub(crate) python: String,
    /// What to install, ending every error of a helper that cannot run.
    pub(crate) hint: &'static str,
}

impl Helpers {
    /// With [`python`].
    pub(crate) fn new(hint: &'static str) -> Helpers {
        Helpers {
            python: python(),
            hint,
        }
    }

    /// Runs `python scripts/ros2/<name> args…` with `input` (JSON) on its
    /// stdin, and parses its JSON output; an error that it cannot run or
    /// failed (with its stderr) names what to install.
    pub(crate) fn run(
        &self,
        name: &str,
        args: &[&str],
        input: Option<&Value>,
    ) -> Result<Value, String> {
        let Helpers { python, hint } = self;
        let mut child = Command::new(python)
            .arg(script(name))
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| format!("cannot run `{python}`: {e}; {hint}"))?;
        if let Some(input) = input {
            let mut stdin = child.stdin.take().ok_or("no stdin")?;
            stdin
                .write_all(input.to_string().as_bytes())
                .map_err(|e| format!("writing to {python}: {e}"))?;
        }
        drop(child.stdin.take());
        let out = child
            .wait_with_output()
            .map_err(|e| format!("waiting for {python}: {e}"))?;
        if !out.status.success() {
            return Err(format!(
                "`{python} {name} {}` failed ({}): {}\n{hint}",
                args.join(" "),
                out.status,
                String::from_utf8_lossy(&out.stderr).trim()
            ));
        }
        serde_json::from_slice(&out.stdout).map_err(|e| format!("bad JSON from {name}: {e}"))
    }
}

/// Checks that a helper run with an interpreter that does not exist fails
/// saying what to install (`hint`): `scripts/test`, and the binary's
/// `requirements` file.
pub(crate) fn assert_missing_interpreter_named(hint: &'static str, requirements: &str) {
    let missing = Helpers {
        python: "/nonexistent/python3".to_owned(),
        hint,
    };
    let err = missing
        .run("msg_definitions.py", &[], None)
        .expect_err("cannot run");
    assert!(err.contains("scripts/test"), "{err}");
    assert!(err.contains(requirements), "{err}");
}
