//! `robot.toml`: everything one robot process needs, in one typed file
//! ([`RobotFile`]) — the one way a robot process is configured
//! (`echelon fleet robot --config robot.toml`). `fleet bundle` writes one
//! per on-board robot (with the scenario beside it, [`crate::bundle`]);
//! `fleet up` writes one per robot it starts itself (`OUT/robots/`); the
//! command-line form of `fleet robot` builds the same type.
//!
//! Paths in the file (the scenario, the certificates, the operator token, a
//! Zenoh configuration) are relative to the file's directory. The
//! scenario's SHA-256 is in the file: a robot refuses to run a scenario
//! other than the one its file was made for (one line, nothing moves).

use std::path::{Path, PathBuf};

use echelon::scenario::{Scenario, check_endpoint, check_listen_endpoint, is_valid_fleet_name};
use serde::{Deserialize, Serialize};

use crate::FleetError;
use crate::faults::FaultSpec;
use crate::net::{Mode, NetOptions, Secure};
use crate::options::ProcessOptions;
use crate::role::Member;
use crate::token::OperatorToken;

use super::RobotOptions;

/// The file format's version (`version = 1`).
pub const ROBOT_FILE_VERSION: u32 = 1;
/// The file's usual name.
pub const ROBOT_FILE: &str = "robot.toml";

/// A robot process's configuration (`robot.toml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotFile {
    /// The format's version ([`ROBOT_FILE_VERSION`]).
    pub version: u32,
    /// The scenario: a path (relative to the file) or a built-in name.
    pub scenario: String,
    /// SHA-256 of the scenario's text, lowercase hex: the robot refuses
    /// any other scenario.
    pub scenario_sha256: String,
    /// Which agent of the scenario, from 1.
    pub agent: u32,
    /// The fleet's name, when not the scenario's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fleet: Option<String>,
    /// What it drives.
    pub drive: Drive,
    /// The fleet clock.
    #[serde(default)]
    pub clock: ClockSection,
    /// How it joins the fleet (the hub's router).
    pub net: NetSection,
    /// Secure mode: mutual TLS and access control.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub secure: Option<SecureSection>,
    /// The operator token's file (it obeys only resumes signed with it;
    /// absent or missing file: `ECHELON_OPERATOR_TOKEN`, else it obeys no
    /// resume and says so).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub operator_token: Option<String>,
    /// Faults injected for a rehearsal (the fault matrix: `[rehearsal]`,
    /// every field of [`FaultSpec`] optional); never in a bundle.
    #[serde(default, skip_serializing_if = "is_no_fault")]
    pub rehearsal: FaultSpec,
}

/// What the robot process drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Drive {
    /// A simulated robot in the process, paced by the fleet clock.
    Simulated,
    /// The agent's real ROS 2 robot (`[fleet.ros2]`), at its own router
    /// when the agent names one; real time only.
    Ros2,
    /// A simulated ROS 2 base (`fleet base --ros2`) on the fleet's network,
    /// whose clock may run faster.
    Ros2Simulated,
}

/// `[clock]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClockSection {
    /// The clock's speed-up (1: real time).
    pub time_scale: f64,
    /// Stop at this fleet time, s (absent: at SIGINT/SIGTERM).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duration: Option<f64>,
    /// A rehearsal's `kill -9`: the process kills itself with SIGKILL at
    /// this fleet time (the fault matrix).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub die_at: Option<f64>,
}

impl Default for ClockSection {
    fn default() -> Self {
        ClockSection {
            time_scale: 1.0,
            duration: None,
            die_at: None,
        }
    }
}

fn is_no_fault(f: &FaultSpec) -> bool {
    *f == FaultSpec::default()
}

/// `[net]`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetSection {
    /// `client` (one link, to the hub's router: the usual) or `peer`.
    pub mode: NetMode,
    /// Endpoints to connect to: the hub's router (tried in order).
    pub connect: Vec<String>,
    /// Endpoints to listen on (a peer).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub listen: Vec<String>,
    /// A Zenoh configuration file (JSON5) to start from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zenoh_config: Option<String>,
}

/// A robot's Zenoh mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NetMode {
    /// A client of one router.
    Client,
    /// A peer.
    Peer,
}

/// `[secure]`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SecureSection {
    /// The certificates' directory (`ca.pem`, `<identity>.pem`, `<identity>.key`).
    pub dir: String,
    /// Its identity (`robot-<k>`).
    pub identity: String,
    /// Robot identities the access control knows.
    pub robots: u32,
}

/// SHA-256 of `text`, lowercase hex: a scenario's fingerprint.
pub fn sha256_hex(text: &str) -> String {
    ring::digest::digest(&ring::digest::SHA256, text.as_bytes())
        .as_ref()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// A robot file with the directory its relative paths start from.
#[derive(Debug, Clone)]
pub struct LoadedRobotFile {
    /// The file's contents, checked.
    pub file: RobotFile,
    /// Its directory.
    pub dir: PathBuf,
    /// Where it came from (errors name it).
    pub origin: String,
}

impl RobotFile {
    /// The file as TOML, after a comment header (`header`, one `# ` line
    /// each).
    pub fn to_toml(&self, header: &[String]) -> Result<String, FleetError> {
        let body = toml::to_string(self)
            .map_err(|e| FleetError::Config(format!("writing robot.toml: {e}")))?;
        let mut out = String::new();
        for line in header {
            out.push_str("# ");
            out.push_str(line);
            out.push('\n');
        }
        if !header.is_empty() {
            out.push('\n');
        }
        out.push_str(&body);
        Ok(out)
    }

    /// Parses `text` (`origin` names it in errors) and checks every value
    /// that does not need the scenario.
    pub fn parse(text: &str, origin: &str) -> Result<RobotFile, FleetError> {
        let file: RobotFile = toml::from_str(text).map_err(|e| {
            let at = match e.span() {
                Some(span) => {
                    let (line, col) = line_col(text, span.start);
                    format!("{origin}:{line}:{col}")
                }
                None => origin.to_owned(),
            };
            FleetError::Config(format!("{at}: {}", e.message()))
        })?;
        file.check(origin)?;
        Ok(file)
    }

    /// Reads and checks `path`.
    pub fn load(path: &Path) -> Result<LoadedRobotFile, FleetError> {
        let origin = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(FleetError::io(path))?;
        let file = RobotFile::parse(&text, &origin)?;
        let dir = path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."));
        Ok(LoadedRobotFile { file, dir, origin })
    }

    fn check(&self, origin: &str) -> Result<(), FleetError> {
        let bad =
            |field: &str, why: String| Err(FleetError::Config(format!("{origin}: {field}: {why}")));
        if self.version != ROBOT_FILE_VERSION {
            return bad(
                "version",
                format!(
                    "{} is not a version this echelon reads ({ROBOT_FILE_VERSION}): make the bundle again with this echelon",
                    self.version
                ),
            );
        }
        if self.agent == 0 {
            return bad("agent", "agents are numbered from 1".into());
        }
        if self.scenario_sha256.len() != 64
            || !self.scenario_sha256.bytes().all(|b| b.is_ascii_hexdigit())
        {
            return bad("scenario_sha256", "not a SHA-256 (64 hex digits)".into());
        }
        if let Some(f) = &self.fleet
            && !is_valid_fleet_name(f)
        {
            return bad(
                "fleet",
                format!("`{f}`: letters, digits, '-', '_' and '.' only"),
            );
        }
        if !(self.clock.time_scale.is_finite() && self.clock.time_scale > 0.0) {
            return bad(
                "clock.time_scale",
                format!("{} must be > 0", self.clock.time_scale),
            );
        }
        if self.drive == Drive::Ros2 && self.clock.time_scale != 1.0 {
            return bad(
                "clock.time_scale",
                format!(
                    "{}: a real ROS 2 robot runs in real time (drive = \"ros2-simulated\" rehearses faster)",
                    self.clock.time_scale
                ),
            );
        }
        if let Some(d) = self.clock.duration
            && !(d.is_finite() && d > 0.0)
        {
            return bad("clock.duration", format!("{d} must be > 0"));
        }
        if self.net.mode == NetMode::Client && self.net.connect.is_empty() {
            return bad(
                "net.connect",
                "a client needs the hub's endpoint (e.g. [\"tcp/192.168.1.10:7447\"])".into(),
            );
        }
        for e in &self.net.connect {
            check_endpoint(e).or_else(|why| bad("net.connect", why))?;
        }
        for e in &self.net.listen {
            check_listen_endpoint(e).or_else(|why| bad("net.listen", why))?;
        }
        if let Some(s) = &self.secure {
            let own = Member::Robot(self.agent).identity();
            if s.identity != own {
                return bad(
                    "secure.identity",
                    format!(
                        "`{}` is not agent {}'s identity `{own}`",
                        s.identity, self.agent
                    ),
                );
            }
            if s.robots < self.agent {
                return bad(
                    "secure.robots",
                    format!("{} is fewer than agent {}", s.robots, self.agent),
                );
            }
        }
        Ok(())
    }
}

impl LoadedRobotFile {
    /// A path of the file, resolved against its directory.
    fn path(&self, p: &str) -> PathBuf {
        let p = Path::new(p);
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.dir.join(p)
        }
    }

    /// The scenario, checked against the file's hash and agent: a path
    /// beside the file, else a built-in name.
    pub fn scenario(&self) -> Result<Scenario, FleetError> {
        let f = &self.file;
        let beside = self.path(&f.scenario);
        let scenario = if beside.is_file() {
            Scenario::load(&beside)?
        } else {
            Scenario::resolve(&f.scenario)?
        };
        let hash = sha256_hex(scenario.source());
        if hash != f.scenario_sha256 {
            return Err(FleetError::Config(format!(
                "{}: scenario_sha256: {} is not the scenario this file was made for (its SHA-256 is {hash}): make the bundle again from the fleet's scenario (`echelon fleet bundle`)",
                self.origin, f.scenario
            )));
        }
        let n = scenario.file.agents.len();
        if f.agent as usize > n {
            return Err(FleetError::Config(format!(
                "{}: agent: {} is not an agent of {} (agents 1..={n})",
                self.origin, f.agent, f.scenario
            )));
        }
        Ok(scenario)
    }

    /// Its session options.
    pub fn net(&self) -> NetOptions {
        let f = &self.file;
        NetOptions {
            mode: Some(match f.net.mode {
                NetMode::Client => Mode::Client,
                NetMode::Peer => Mode::Peer,
            }),
            listen: f.net.listen.clone(),
            connect: f.net.connect.clone(),
            zenoh_config: f.net.zenoh_config.as_deref().map(|p| self.path(p)),
            secure: f.secure.as_ref().map(|s| Secure {
                dir: self.path(&s.dir),
                identity: s.identity.clone(),
                robots: s.robots,
                ros2: Vec::new(),
            }),
        }
    }

    /// The operator token: from the file named in `operator_token` when it
    /// exists, else `ECHELON_OPERATOR_TOKEN`, else none.
    pub fn operator_token(&self) -> Result<Option<OperatorToken>, FleetError> {
        if let Some(p) = &self.file.operator_token {
            let path = self.path(p);
            if path.is_file() {
                return OperatorToken::from_file(&path).map(Some);
            }
        }
        OperatorToken::from_env()
    }

    /// The same, reaching the fleet as a client of `hub` instead of its
    /// file's network (`--hub`; empty: its file's network).
    pub fn with_hub(mut self, hub: &[String]) -> LoadedRobotFile {
        if !hub.is_empty() {
            self.file.net = NetSection {
                mode: NetMode::Client,
                connect: hub.to_vec(),
                listen: Vec::new(),
                zenoh_config: None,
            };
        }
        self
    }

    /// The robot process's options: the scenario checked, the session
    /// (its access control with the scenario's ROS 2 topics), the token.
    pub fn options(&self) -> Result<RobotOptions, FleetError> {
        let scenario = self.scenario()?;
        let mut net = self.net();
        if let Some(s) = net.secure.as_mut() {
            s.ros2 = crate::net::ros_acl(&scenario.fleet()?.ros2);
        }
        let f = &self.file;
        Ok(RobotOptions {
            process: ProcessOptions {
                scenario,
                time_scale: f.clock.time_scale,
                duration: f.clock.duration,
                net,
                fleet: f.fleet.clone(),
                die_at: f.clock.die_at,
            },
            agent: f.agent,
            faults: f.rehearsal,
            ros2: f.drive != Drive::Simulated,
            own_router: f.drive == Drive::Ros2,
            operator_token: self.operator_token()?,
        })
    }
}

/// 1-based line and column of byte `at` in `text`.
fn line_col(text: &str, at: usize) -> (usize, usize) {
    let before = text.get(..at).unwrap_or(text);
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

#[cfg(test)]
mod tests;
