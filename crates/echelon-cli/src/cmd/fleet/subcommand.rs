//! The `echelon fleet` subcommands (clap): each takes the arguments of a
//! fleet process ([`super::args`]) or of an operator's command
//! ([`super::operator_args`]).

use clap::Subcommand;

use super::args::{
    BaseArgs, CollectorArgs, ExciteArgs, GarbageArgs, HeartbeatArgs, HostArgs, IdleArgs,
    LeaderArgs, RobotArgs, RouterArgs,
};
use super::operator_args::{
    BenchArgs, BundleArgs, CertsArgs, CommandArgs, DoctorArgs, FaultsArgs, ResumeArgs, StatusArgs,
    UpArgs,
};

/// `echelon fleet` subcommands.
#[derive(Debug, Subcommand)]
pub(crate) enum FleetCommand {
    /// Publish the scenario's reference (the virtual leader).
    Leader(LeaderArgs),
    /// Run one agent of the scenario: control law on a simulated plant paced in real time, or on a ROS 2 robot (--ros2).
    Robot(RobotArgs),
    /// Run many simulated robots in one process (one Zenoh session, one timer): each keeps its own keys, tokens, counters and report, as `fleet robot` alone; one robot's failure stops it only.
    Host(HostArgs),
    /// The machine's floor for `fleet bench`: a bare process that only wakes at --rate Hz for --duration s, then prints its CPU seconds.
    #[command(hide = true)]
    Idle(IdleArgs),
    /// A simulated ROS 2 base (--ros2): cmd_vel in, odom out over rmw_zenoh, as diff_drive_controller on a robot.
    Base(BaseArgs),
    /// Drive one ROS 2 robot's cmd_vel with steps and chirps within its limits (--ros2) and record cmd_vel and odom to a bag for `echelon identify`.
    Excite(ExciteArgs),
    /// Record everything to DIR/fleet.mcap and DIR/trajectory.csv.
    Collector(CollectorArgs),
    /// A Zenoh router (the engine of zenohd) for the fleet's processes to link to; runs until SIGINT/SIGTERM.
    Router(RouterArgs),
    /// Start a router, a leader, one process per robot and a collector on loopback (with --ros2 --real, driving real robots at their own routers); stop them; summarise.
    #[command(allow_negative_numbers = true)]
    Up(UpArgs),
    /// Stop every robot of the fleet (latched: they command zero until `fleet resume`); exits 0 once every robot alive has acknowledged.
    Stop(CommandArgs),
    /// Lift a `fleet stop`: the robots follow again from where they are, the leader's reference goes on from where it paused. Needs the operator token (--token-file OUT/operator-token, --token or ECHELON_OPERATOR_TOKEN).
    Resume(ResumeArgs),
    /// The running fleet seen from here (any machine that reaches its hub): per robot its state (running, holding, stopped, lost), link age, ‖e‖, last hazard and CPU, and the leader and the collector; exits 1 when no robot is heard.
    Status(StatusArgs),
    /// Before a run, check the hub and every robot without moving any: reachable, clock offset to the hub, round trips, odometry and its rate, cmd_vel reader, fixes, certificates, versions; a table (or --json); exits 1 when a check fails.
    Doctor(DoctorArgs),
    /// The operator's heartbeat, a supervised run's deadman ([fleet] operator_heartbeat = T): robots hold while none arrived for T s; runs until --duration or SIGINT/SIGTERM.
    Heartbeat(HeartbeatArgs),
    /// Put garbage, duplicates and replays on every key of the fleet from fleet time --from for --for seconds (a rehearsal of hostile input: the fleet must count and refuse it); runs until SIGINT/SIGTERM.
    Garbage(GarbageArgs),
    /// Run the fault matrix (docs/faults.md): each fault on a simulated fleet over real Zenoh, the travel after it measured against its bound; writes DIR/faults.md and DIR/faults.json.
    Faults(FaultsArgs),
    /// Write each on-board robot's directory (robot.toml, the scenario, a launcher, a systemd unit, its certificates) for `fleet robot --config` on the robot's computer.
    Bundle(BundleArgs),
    /// Make a development CA and certificates for the secure mode.
    Certs(CertsArgs),
    /// Run `fleet up` for several fleet sizes on loopback at time scale 1 and tabulate startup, CPU, messages/s, latency, losses and final error.
    #[command(allow_negative_numbers = true)]
    Bench(BenchArgs),
}
