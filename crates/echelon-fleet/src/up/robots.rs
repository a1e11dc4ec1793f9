//! The robot files (`OUT/robots/robot-<k>.toml`, [`RobotFile`]) of the
//! robots `fleet up` starts itself: each robot process is started as
//! `fleet robot --config FILE`, the same file type an on-board robot's
//! bundle holds.

use std::path::{Path, PathBuf};

use crate::FleetError;
use crate::faults::FaultSpec;
use crate::robot::{
    ClockSection, Drive, NetSection, ROBOT_FILE_VERSION, RobotFile, SecureSection, sha256_hex,
};
use crate::role::Member;

use super::UpOptions;

/// The directory of the robot files, under the output directory.
pub const ROBOTS_DIR: &str = "robots";

/// `path` absolute (against the working directory), as a robot file names
/// what lies outside its own directory.
fn absolute(path: &Path) -> Result<PathBuf, FleetError> {
    std::path::absolute(path).map_err(FleetError::io(path))
}

/// What robot `k` is given from `opts`' faults and chaos (a rehearsal).
fn rehearsal(opts: &UpOptions, k: u32) -> FaultSpec {
    let chaos = &opts.chaos;
    let own_outage = chaos.outages.iter().find(|(j, _)| *j == k).map(|&(_, w)| w);
    FaultSpec {
        outage: own_outage.or(opts.faults.outage),
        freeze_odometry: chaos
            .freeze_odometry
            .iter()
            .find(|(j, _)| *j == k)
            .map(|&(_, w)| w),
        wall_clock_jump: chaos
            .wall_clock_jumps
            .iter()
            .find(|(j, _)| *j == k)
            .map(|&(_, w)| w),
        partition: chaos
            .partitions
            .iter()
            .find(|(j, _)| *j == k)
            .map(|&(_, w)| w),
        fault_at: chaos.fault_at,
        fault_window: chaos.fault_at.and(chaos.window),
        ..opts.faults
    }
}

/// Robot `k`'s file, written to `OUT/robots/robot-<k>.toml`: its scenario
/// (by absolute path, or a built-in's name) with its hash, its drive, the
/// fleet clock to `duration`, its session `net`, the certificates and the
/// operator token's file.
pub(super) fn write_robot_file(
    opts: &UpOptions,
    scenario: &echelon::scenario::Scenario,
    k: u32,
    robots: u32,
    duration: f64,
    net: NetSection,
    token_file: &Path,
) -> Result<PathBuf, FleetError> {
    let as_path = Path::new(&opts.scenario);
    let scenario_ref = match as_path.is_file() {
        true => absolute(as_path)?.display().to_string(),
        false => opts.scenario.clone(),
    };
    let drive = match (opts.ros2, opts.real) {
        (false, _) => Drive::Simulated,
        (true, true) => Drive::Ros2,
        (true, false) => Drive::Ros2Simulated,
    };
    let secure = match &opts.secure {
        Some(dir) => Some(SecureSection {
            dir: absolute(dir)?.display().to_string(),
            identity: Member::Robot(k).identity(),
            robots,
        }),
        None => None,
    };
    let file = RobotFile {
        version: ROBOT_FILE_VERSION,
        scenario: scenario_ref,
        scenario_sha256: sha256_hex(scenario.source()),
        agent: k,
        fleet: None,
        drive,
        clock: ClockSection {
            time_scale: opts.time_scale,
            duration: Some(duration),
            die_at: opts.chaos.death_of(Member::Robot(k)),
        },
        net,
        secure,
        operator_token: Some(absolute(token_file)?.display().to_string()),
        rehearsal: rehearsal(opts, k),
    };
    let dir = opts.out.join(ROBOTS_DIR);
    std::fs::create_dir_all(&dir).map_err(FleetError::io(&dir))?;
    let path = dir.join(format!("robot-{k}.toml"));
    let header = [format!(
        "robot {k}, started by `echelon fleet up` on the hub: `echelon fleet robot --config {}`",
        path.display()
    )];
    let text = file.to_toml(&header)?;
    std::fs::write(&path, text).map_err(FleetError::io(&path))?;
    Ok(path)
}
