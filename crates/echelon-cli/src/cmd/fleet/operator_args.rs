//! The arguments of what an operator runs against a whole fleet (clap):
//! `up` and `bench` on loopback, the fault matrix, `bundle` and `certs`
//! before a run, `stop`, `resume`, `status` and `doctor` during one. The
//! fleet's own processes' arguments are in [`super::args`].

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use echelon_fleet::token::OperatorToken;

use super::args::{ClockArgs, FaultArgs, LiveArgs, NetArgs, connect_endpoint, listen_endpoint};
use crate::cmd::{parse_number, positive, seconds, time_scale};

/// `echelon fleet faults`.
#[derive(Debug, Args)]
pub(crate) struct FaultsArgs {
    /// Where each row's fleet runs (DIR/<row>/) and the table goes (DIR/faults.md, DIR/faults.json).
    #[arg(long, value_name = "DIR")]
    pub(super) out: std::path::PathBuf,
    /// Only the row of this name (repeatable) [default: every row].
    #[arg(long, value_name = "NAME")]
    pub(super) only: Vec<String>,
    /// Run each row's clock K times faster than real time.
    #[arg(long, value_name = "K", value_parser = time_scale, default_value_t = 1.0)]
    pub(super) time_scale: f64,
}

/// How `fleet up` links its processes.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub(super) enum TopologyArg {
    /// A router per site; every process a Zenoh client with one link to its site's router.
    Router,
    /// Every process a peer linked to every other (N² links; a handful of robots).
    Mesh,
}

/// `echelon fleet up`.
#[derive(Debug, Args)]
#[command(
    mut_arg("foxglove", |a| a.help(
        "Serve the live fleet to Foxglove (its WebSocket protocol) on ADDR [default: 127.0.0.1:8765; port 0: any free port]: \
         the collector's channels and the 3D ones (docs/foxglove.md); the address is in DIR/endpoints.json"
    )),
    mut_arg("log_rate", |a| a.help(
        "The collector's state-log rate: at most HZ states per robot per second (`fleet collector --log-rate`) [default: every state]"
    )),
)]
pub(crate) struct UpArgs {
    /// A built-in scenario name or a path to a .toml file.
    pub(super) scenario: String,
    /// Output directory.
    #[arg(long, value_name = "DIR")]
    pub(super) out: PathBuf,
    #[command(flatten)]
    pub(super) clock: ClockArgs,
    #[command(flatten)]
    pub(super) faults: FaultArgs,
    /// Secure mode with the certificates in DIR (`echelon fleet certs DIR`).
    #[arg(long, value_name = "DIR")]
    pub(super) secure: Option<PathBuf>,
    /// Robots drive simulated ROS 2 bases (one `fleet base --ros2` each), all robot↔base traffic in ROS 2's format.
    #[arg(long)]
    pub(super) ros2: bool,
    /// With --ros2 (simulated bases): base K reports a hazard over a window of its clock (started with the fleet, a moment before the leader), K:NAME@FROM+DURATION (2:BUMP@12+3; EMERGENCY_STOP is an e-stop) (repeatable).
    #[arg(long, value_name = "K:NAME@FROM+S", value_parser = parse_agent_hazard)]
    pub(super) hazard: Vec<(u32, echelon_fleet::ros2::hazard::HazardWindow)>,
    /// With --ros2: drive real robots, each at its own router (the agents' `ros2.connect`), instead of simulated bases; real time only.
    #[arg(long, requires = "ros2")]
    pub(super) real: bool,
    /// How the processes link.
    #[arg(long, value_enum, default_value = "router")]
    pub(super) topology: TopologyArg,
    /// Router topology: S routers linked to each other (sites on loopback), robots spread over them.
    #[arg(long, value_name = "S", default_value_t = 1)]
    pub(super) sites: usize,
    /// The collector's, which `up` starts.
    #[command(flatten)]
    pub(super) live: LiveArgs,
    /// Hub mode: router, leader and collector on this machine, the router listening on --listen; robots with placement = "onboard" join from their computers (`fleet bundle`), and the reference starts once every robot joined.
    #[arg(long, requires = "listen")]
    pub(super) hub: bool,
    /// With --hub: where its router listens, e.g. tcp/0.0.0.0:7447 (quic/… in secure mode) (repeatable).
    #[arg(long, value_name = "ENDPOINT", value_parser = listen_endpoint, requires = "hub")]
    pub(super) listen: Vec<String>,
    /// With --hub: the longest wait for every robot to join, s of real time; then exit 1 naming the missing ones.
    #[arg(long, value_name = "S", value_parser = seconds, default_value_t = 120.0, requires = "hub")]
    pub(super) wait: f64,
    /// The operator token in this file (e.g. the one given to `fleet bundle`) [default: ECHELON_OPERATOR_TOKEN, else a new one].
    #[arg(long, value_name = "PATH")]
    pub(super) token_file: Option<PathBuf>,
    /// Simulated robots per robot process (`fleet host`) [default: 1 up to 16 robots, else a few processes per core; always 1 with --ros2, --secure or --topology mesh].
    #[arg(long, value_name = "K")]
    pub(super) robots_per_process: Option<usize>,
    /// Print nothing but errors.
    #[arg(long, short)]
    pub(super) quiet: bool,
}

/// `echelon fleet bench`.
#[derive(Debug, Args)]
pub(crate) struct BenchArgs {
    /// Output directory: DIR/nNNN/ per size, DIR/bench.json and DIR/bench.md.
    #[arg(long, value_name = "DIR")]
    pub(super) out: PathBuf,
    /// Fleet sizes to run, in order (robots behind a circle, generated).
    #[arg(long, value_name = "N,…", value_delimiter = ',', default_values_t = [10, 50, 100, 200])]
    pub(super) robots: Vec<usize>,
    /// Fleet seconds each size runs (real seconds: time scale 1).
    #[arg(long, value_name = "S", value_parser = seconds, default_value_t = 60.0)]
    pub(super) duration: f64,
    /// The collector's state-log rate, states per robot per second (`fleet collector --log-rate`) [default: every state].
    #[arg(long, value_name = "HZ", value_parser = positive)]
    pub(super) log_rate: Option<f64>,
    /// Simulated robots per robot process (`fleet up --robots-per-process`) [default: fleet up's].
    #[arg(long, value_name = "K")]
    pub(super) robots_per_process: Option<usize>,
    /// Also run fleets of K robots all in one host (`fleet host`), for each K given: the marginal CPU of one more robot in a host is the slope between the first and the last (`--hosts` with no value: none).
    #[arg(long, value_name = "K,…", value_delimiter = ',', num_args = 0.., default_values_t = [10, 250])]
    pub(super) hosts: Vec<usize>,
    /// Print only the table.
    #[arg(long, short)]
    pub(super) quiet: bool,
}

/// `echelon fleet stop` / `echelon fleet resume`.
#[derive(Debug, Args)]
pub(crate) struct CommandArgs {
    /// The scenario, for the fleet name (and the access control's robot count in secure mode), or give --fleet.
    pub(super) scenario: Option<String>,
    /// Why, in a few words (carried by the command and logged by the collector).
    #[arg(long, value_name = "TEXT", default_value = "")]
    pub(super) reason: String,
    /// Longest wait for every robot alive to acknowledge, s of real time; exit status 1 if one did not.
    #[arg(long, value_name = "S", value_parser = seconds, default_value_t = 5.0)]
    pub(super) timeout: f64,
    #[command(flatten)]
    pub(super) net: NetArgs,
}

/// `echelon fleet resume`: a command signed with the operator token.
#[derive(Debug, Args)]
pub(crate) struct ResumeArgs {
    #[command(flatten)]
    pub(super) command: CommandArgs,
    /// The operator token, 32 hexadecimal characters (other users may see it in the process list: prefer --token-file or ECHELON_OPERATOR_TOKEN).
    #[arg(long, value_name = "HEX", conflicts_with = "token_file")]
    pub(super) token: Option<String>,
    /// A file holding the operator token (`fleet up` writes OUT/operator-token) [default: ECHELON_OPERATOR_TOKEN].
    #[arg(long, value_name = "PATH")]
    pub(super) token_file: Option<PathBuf>,
}

impl ResumeArgs {
    /// The operator token: --token, --token-file, else ECHELON_OPERATOR_TOKEN
    /// (`None`: none given).
    pub(super) fn operator_token(&self) -> Result<Option<OperatorToken>> {
        Ok(match (&self.token, &self.token_file) {
            (Some(hex), _) => Some(OperatorToken::parse(hex.trim()).context("--token")?),
            (None, Some(path)) => Some(OperatorToken::from_file(path).context("--token-file")?),
            (None, None) => OperatorToken::from_env()?,
        })
    }
}

/// `echelon fleet bundle`.
#[derive(Debug, Args)]
pub(crate) struct BundleArgs {
    /// A built-in scenario name or a path to a .toml file.
    pub(super) scenario: String,
    /// The hub's router endpoint, as `fleet up --hub --listen` listens (repeatable: tried in order), e.g. tcp/192.168.1.10:7447.
    #[arg(long, value_name = "ENDPOINT", value_parser = connect_endpoint, required = true)]
    pub(super) hub: Vec<String>,
    /// Output directory: one robot-K/ per on-board robot.
    #[arg(long, value_name = "DIR")]
    pub(super) out: PathBuf,
    /// Every agent, not only those with placement = "onboard".
    #[arg(long)]
    pub(super) all: bool,
    /// The robots drive a simulated robot (a rehearsal without hardware), not their ROS 2 robot.
    #[arg(long)]
    pub(super) simulated: bool,
    /// With --simulated: run the clock K times faster (the hub's `fleet up --time-scale`).
    #[arg(long, value_name = "K", value_parser = time_scale, default_value_t = 1.0, requires = "simulated")]
    pub(super) time_scale: f64,
    /// The robots stop at this fleet time, s [default: at SIGTERM, as a service].
    #[arg(long, value_name = "S", value_parser = seconds)]
    pub(super) duration: Option<f64>,
    /// Secure mode: copy the CA and each robot's own certificate and key from DIR (`echelon fleet certs`).
    #[arg(long, value_name = "DIR")]
    pub(super) secure: Option<PathBuf>,
    /// Copy the operator token in this file (the hub's OUT/operator-token) into each robot's directory [default: ECHELON_OPERATOR_TOKEN, else none].
    #[arg(long, value_name = "PATH")]
    pub(super) token_file: Option<PathBuf>,
    /// Fleet name [default: the scenario's].
    #[arg(long, value_name = "NAME")]
    pub(super) fleet: Option<String>,
    /// Where the robots' directories go on their computers (the systemd unit's paths).
    #[arg(long, value_name = "DIR", default_value = echelon_fleet::bundle::DEFAULT_INSTALL_DIR)]
    pub(super) install_dir: String,
}

/// `echelon fleet certs`.
#[derive(Debug, Args)]
pub(crate) struct CertsArgs {
    /// Output directory.
    pub(super) dir: PathBuf,
    /// Number of robot identities (robot-1 … robot-N).
    #[arg(long, value_name = "N", default_value_t = 4)]
    pub(super) robots: u32,
    /// Another host name or IP address the fleet's processes listen on (repeatable).
    #[arg(long, value_name = "HOST")]
    pub(super) host: Vec<String>,
    /// Rehearsals of `fleet doctor`'s findings: identity ID's certificate expires DAYS days from now (negative: expired already) (repeatable).
    #[arg(long, value_name = "ID=DAYS", value_parser = parse_expiry, allow_hyphen_values = true, hide = true)]
    pub(super) expires: Vec<(String, f64)>,
}

/// `ID=DAYS` of `fleet certs --expires`.
fn parse_expiry(s: &str) -> Result<(String, f64), String> {
    let (id, days) = s
        .split_once('=')
        .ok_or_else(|| format!("`{s}`: give ID=DAYS, e.g. robot-1=-1"))?;
    Ok((id.to_owned(), parse_number(days)?))
}

/// `echelon fleet doctor`.
#[derive(Debug, Args)]
pub(crate) struct DoctorArgs {
    /// A built-in scenario name or a path to a .toml file: the fleet to check.
    pub(super) scenario: String,
    /// Listen to each robot's odometry and fixes, and probe each process, this long, s of real time.
    #[arg(long, value_name = "S", value_parser = positive, default_value_t = 3.0)]
    pub(super) listen_for: f64,
    /// Longest wait to reach an endpoint (the hub, a robot's router) or for a probe's answer, s of real time.
    #[arg(long, value_name = "S", value_parser = positive, default_value_t = 3.0)]
    pub(super) timeout: f64,
    /// Print the findings as one JSON document.
    #[arg(long)]
    pub(super) json: bool,
    #[command(flatten)]
    pub(super) net: NetArgs,
}

/// `K:NAME@FROM+DURATION`: agent K's simulated base reports a hazard.
fn parse_agent_hazard(s: &str) -> Result<(u32, echelon_fleet::ros2::hazard::HazardWindow), String> {
    let (k, window) = s
        .split_once(':')
        .ok_or_else(|| format!("`{s}`: give K:NAME@FROM+DURATION, e.g. 2:BUMP@12+3"))?;
    let k: u32 = k
        .parse()
        .ok()
        .filter(|k| *k >= 1)
        .ok_or_else(|| format!("`{s}`: `{k}` is not an agent number (1, 2, …)"))?;
    Ok((k, window.parse()?))
}

/// `echelon fleet status`.
#[derive(Debug, Args)]
pub(crate) struct StatusArgs {
    /// The scenario, for the fleet name and its robots (each listed, heard or not), or give --fleet.
    pub(super) scenario: Option<String>,
    /// Redraw every second until SIGINT/SIGTERM.
    #[arg(long)]
    pub(super) watch: bool,
    /// Print one JSON document (with --watch, one line per refresh).
    #[arg(long)]
    pub(super) json: bool,
    /// How long to listen before answering (and to wait for the endpoints), s of real time.
    #[arg(long, value_name = "S", value_parser = seconds, default_value_t = echelon_fleet::status::DEFAULT_LISTEN.as_secs_f64())]
    pub(super) listen_for: f64,
    #[command(flatten)]
    pub(super) net: NetArgs,
}
