//! `echelon fleet bundle`: what each on-board robot's computer needs to
//! join the hub, one directory per robot (`OUT/robot-<k>/`):
//!
//! - `robot.toml`: its whole configuration ([`RobotFile`]: agent, drive,
//!   the hub's endpoints, certificates, the scenario's SHA-256), with a
//!   header naming its ROS 2 topics and its robot's router;
//! - `scenario.toml`: the scenario, byte for byte;
//! - `echelon-robot.sh`: the launcher (`fleet robot --config robot.toml`);
//! - `echelon-robot-<k>.service`: a systemd unit running the launcher from
//!   the install directory, restarted on failure;
//! - `certs/` in secure mode: the CA and the robot's own certificate and key
//!   (no other member's key);
//! - `operator-token`, when the operator's token is given.
//!
//! Same scenario and options, same bytes: nothing random, no time stamps.

use std::path::{Path, PathBuf};

use echelon::scenario::{Overrides, Placement, Ros2Link, Scenario, check_endpoint};

use crate::FleetError;
use crate::faults::FaultSpec;
use crate::robot::{
    ClockSection, Drive, NetMode, NetSection, ROBOT_FILE, ROBOT_FILE_VERSION, RobotFile,
    SecureSection, sha256_hex,
};
use crate::role::Member;
use crate::token::{OperatorToken, TOKEN_FILE};

/// The scenario's copy in a robot's directory.
pub const SCENARIO_FILE: &str = "scenario.toml";
/// The launcher in a robot's directory.
pub const LAUNCHER_FILE: &str = "echelon-robot.sh";
/// Where the systemd unit expects the robot's directory by default.
pub const DEFAULT_INSTALL_DIR: &str = "/opt/echelon";

/// Options of `fleet bundle`.
#[derive(Debug, Clone)]
pub struct BundleOptions {
    /// The scenario (name or path).
    pub scenario: String,
    /// The hub's router endpoints, as `fleet up --hub` listens.
    pub hub: Vec<String>,
    /// Output directory.
    pub out: PathBuf,
    /// Bundle every agent, not only those with `placement = "onboard"`.
    pub all: bool,
    /// The robots drive a simulated robot (a rehearsal without hardware),
    /// not their ROS 2 robot.
    pub simulated: bool,
    /// With `simulated`: the clock's speed-up.
    pub time_scale: f64,
    /// The robots stop at this fleet time (absent: at SIGTERM, as a
    /// service does).
    pub duration: Option<f64>,
    /// Certificates directory: secure mode.
    pub secure: Option<PathBuf>,
    /// The fleet's operator token, copied into each robot's directory.
    pub token: Option<OperatorToken>,
    /// The fleet name, when not the scenario's.
    pub fleet: Option<String>,
    /// Where the robots' directories are installed on their computers
    /// (the systemd unit's paths): `<install_dir>/robot-<k>`.
    pub install_dir: String,
}

/// What `fleet bundle` wrote.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BundleReport {
    /// The scenario's SHA-256.
    pub scenario_sha256: String,
    /// Each robot's directory, by agent.
    pub robots: Vec<(u32, PathBuf)>,
}

/// Writes the bundle: one directory per on-board robot (every robot with
/// `all`). Refuses (nothing written) a scenario with no on-board robot, an
/// endpoint that is not one, or missing certificates.
pub fn write(opts: &BundleOptions) -> Result<BundleReport, FleetError> {
    let scenario = Scenario::resolve(&opts.scenario)?;
    let settings = scenario.fleet()?;
    let n = scenario.build(&Overrides::default())?.plan.agents().len() as u32;
    check_options(opts)?;
    let agents: Vec<u32> = (1..=n)
        .filter(|&k| opts.all || settings.placement[k as usize - 1] == Placement::Onboard)
        .collect();
    if agents.is_empty() {
        return Err(FleetError::Config(format!(
            "{}: no agent has placement = \"onboard\" (set it in [fleet] or an agent, or give --all)",
            scenario.name()
        )));
    }
    let source = scenario.source();
    let hash = sha256_hex(source);
    let fleet_name = opts.fleet.clone().unwrap_or_else(|| settings.name.clone());
    // Every file in memory first: nothing is written when one is missing.
    let mut files: Vec<BundleFile> = Vec::new();
    let mut robots = Vec::new();
    for &k in &agents {
        let dir = opts.out.join(format!("robot-{k}"));
        let secure = match &opts.secure {
            Some(certs) => Some(secure_section(certs, &dir, k, n, &mut files)?),
            None => None,
        };
        let file = robot_file(opts, k, &hash, secure);
        let header = file_header(
            opts,
            k,
            &fleet_name,
            scenario.name(),
            file.drive,
            &settings.ros2[k as usize - 1],
        );
        files.push((
            dir.join(ROBOT_FILE),
            file.to_toml(&header)?.into_bytes(),
            false,
        ));
        files.push((dir.join(SCENARIO_FILE), source.as_bytes().to_vec(), false));
        files.push((
            dir.join(LAUNCHER_FILE),
            launcher(k, &fleet_name).into_bytes(),
            false,
        ));
        let install = format!("{}/robot-{k}", opts.install_dir.trim_end_matches('/'));
        files.push((
            dir.join(format!("echelon-robot-{k}.service")),
            unit(k, &fleet_name, &install).into_bytes(),
            false,
        ));
        if let Some(t) = &opts.token {
            files.push((dir.join(TOKEN_FILE), t.to_hex().into_bytes(), true));
        }
        robots.push((k, dir));
    }
    for (path, bytes, private) in &files {
        write_file(path, bytes, *private)?;
    }
    for (_, dir) in &robots {
        set_mode(&dir.join(LAUNCHER_FILE), 0o755)?;
    }
    Ok(BundleReport {
        scenario_sha256: hash,
        robots,
    })
}

/// A file of the bundle, held in memory until all are: its path, its
/// bytes, and whether it is private (mode 0600).
type BundleFile = (PathBuf, Vec<u8>, bool);

/// `fleet bundle`'s refusals of its options: no hub endpoint or one that is
/// not an endpoint, a time scale that is not > 0 (simulated) or not 1 (real
/// robots).
fn check_options(opts: &BundleOptions) -> Result<(), FleetError> {
    if opts.hub.is_empty() {
        return Err(FleetError::Config(
            "fleet bundle needs the hub's endpoint (--hub tcp/192.168.1.10:7447)".into(),
        ));
    }
    for e in &opts.hub {
        check_endpoint(e).map_err(|why| FleetError::Config(format!("--hub {why}")))?;
    }
    if opts.simulated && !(opts.time_scale.is_finite() && opts.time_scale > 0.0) {
        return Err(FleetError::Config(format!(
            "--time-scale {}: must be > 0",
            opts.time_scale
        )));
    }
    if !opts.simulated && opts.time_scale != 1.0 {
        return Err(FleetError::Config(format!(
            "--time-scale {}: real robots run in real time (give --simulated to rehearse faster)",
            opts.time_scale
        )));
    }
    Ok(())
}

/// Robot `k`'s secure section (of `n` robots), its CA, certificate and key
/// read from `certs` into `files` under `dir/certs` (the key private).
fn secure_section(
    certs: &Path,
    dir: &Path,
    k: u32,
    n: u32,
    files: &mut Vec<BundleFile>,
) -> Result<SecureSection, FleetError> {
    let identity = Member::Robot(k).identity();
    let [ca, cert, key] = crate::net::secure_files(certs, &identity)?;
    for (from, private) in [(ca, false), (cert, false), (key, true)] {
        let name = from.file_name().map(PathBuf::from).unwrap_or_default();
        let bytes = std::fs::read(&from).map_err(FleetError::io(&from))?;
        files.push((dir.join("certs").join(name), bytes, private));
    }
    Ok(SecureSection {
        dir: "certs".into(),
        identity,
        robots: n,
    })
}

/// Robot `k`'s file: the scenario beside it (SHA-256 `hash`), a client of
/// the hub, on the bundle's clock and drive.
fn robot_file(
    opts: &BundleOptions,
    k: u32,
    hash: &str,
    secure: Option<SecureSection>,
) -> RobotFile {
    let drive = match opts.simulated {
        true => Drive::Simulated,
        false => Drive::Ros2,
    };
    RobotFile {
        version: ROBOT_FILE_VERSION,
        scenario: SCENARIO_FILE.into(),
        scenario_sha256: hash.to_owned(),
        agent: k,
        fleet: opts.fleet.clone(),
        drive,
        clock: ClockSection {
            time_scale: opts.time_scale,
            duration: opts.duration,
            die_at: None,
        },
        net: NetSection {
            mode: NetMode::Client,
            connect: opts.hub.clone(),
            listen: Vec::new(),
            zenoh_config: None,
        },
        secure,
        operator_token: Some(TOKEN_FILE.into()),
        rehearsal: FaultSpec::default(),
    }
}

/// The comment heading robot `k`'s file: who it is, how to run it, where it
/// joins, what it drives (its ROS 2 `link`), and the token it needs.
fn file_header(
    opts: &BundleOptions,
    k: u32,
    fleet_name: &str,
    scenario: &str,
    drive: Drive,
    link: &Ros2Link,
) -> Vec<String> {
    let mut header = vec![
        format!(
            "echelon robot {k} of fleet `{fleet_name}` (scenario {scenario}), written by `echelon fleet bundle`."
        ),
        format!("Run it: ./{LAUNCHER_FILE}  (or: echelon fleet robot --config {ROBOT_FILE})"),
        format!("It joins the hub at {}.", opts.hub.join(" or ")),
    ];
    match drive {
        Drive::Simulated => header.push("It drives a simulated robot (a rehearsal).".into()),
        _ => {
            header.push(format!(
                "It drives {} ({}) and reads {} in ROS domain {}, {}.",
                link.cmd_vel,
                crate::ros2::drive::cmd_vel_type(link).name,
                link.odom,
                link.domain_id,
                match link.connect.is_empty() {
                    true => "through the fleet's network".to_owned(),
                    false => format!("at its robot's router {}", link.connect.join(" or ")),
                }
            ));
        }
    }
    if opts.token.is_none() {
        header.push(format!(
            "It obeys `fleet resume` only with the operator token: copy the hub's {TOKEN_FILE} beside this file."
        ));
    }
    header
}

/// The launcher: `fleet robot --config` on the file beside it.
fn launcher(k: u32, fleet: &str) -> String {
    format!(
        "#!/bin/sh\n\
         # echelon robot {k} of fleet `{fleet}`: joins the hub named in robot.toml.\n\
         # ECHELON names the echelon binary (default: the one on PATH).\n\
         here=\"$(cd \"$(dirname \"$0\")\" && pwd)\"\n\
         exec \"${{ECHELON:-echelon}}\" fleet robot --config \"$here/{ROBOT_FILE}\" \"$@\"\n"
    )
}

/// The systemd unit running the launcher from `install`.
fn unit(k: u32, fleet: &str, install: &str) -> String {
    format!(
        "[Unit]\n\
         Description=echelon robot {k} of fleet {fleet}\n\
         Wants=network-online.target\n\
         After=network-online.target\n\
         \n\
         [Service]\n\
         Type=simple\n\
         WorkingDirectory={install}\n\
         ExecStart={install}/{LAUNCHER_FILE}\n\
         # SIGTERM: the robot commands zero, says goodbye and exits.\n\
         KillSignal=SIGTERM\n\
         TimeoutStopSec=10\n\
         Restart=on-failure\n\
         RestartSec=2\n\
         \n\
         [Install]\n\
         WantedBy=multi-user.target\n"
    )
}

fn write_file(path: &Path, bytes: &[u8], private: bool) -> Result<(), FleetError> {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(FleetError::io(parent))?;
    }
    std::fs::write(path, bytes).map_err(FleetError::io(path))?;
    if private {
        set_mode(path, 0o600)?;
    }
    Ok(())
}

fn set_mode(path: &Path, mode: u32) -> Result<(), FleetError> {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode))
        .map_err(FleetError::io(path))
}
