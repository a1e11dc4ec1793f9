//! `echelon identify`: a robot's eq. 3 parameters (torque model) or its
//! velocity base's lags and limits from a logged manoeuvre, as a
//! `[robots.NAME]` block; with `--out`, also `robot.toml`, `identify.json` and
//! a figure of measured against model-predicted velocities.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use echelon::identify::{self, Identified, Log, Model};
use echelon_mcap::bag::BagOptions;
use echelon_report::figure::{Axis, Figure, Panel, Stroke};

use super::out::outln;

/// `--model`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum ModelArg {
    /// `m, η, J, ψ` of eq. 3c–d, from `u1, u2` and the measured `v, ω`.
    Torque,
    /// A velocity base's `τ_v, τ_ω` and limits, from the applied command.
    Velocity,
}

/// Arguments of `echelon identify`.
#[derive(Debug, clap::Args)]
pub(crate) struct IdentifyArgs {
    /// A run directory written by `echelon run` (or its trajectory.csv), or an
    /// MCAP file: a ROS 2 bag with cmd_vel and odom, fleet.mcap or run.mcap.
    #[arg(value_name = "LOG")]
    log: PathBuf,
    /// The model to identify (default: torque if the log has u1, u2, else velocity).
    #[arg(long, value_enum)]
    model: Option<ModelArg>,
    /// The agent whose rows to use (numbered from 1).
    #[arg(long, value_name = "K", default_value_t = 1)]
    agent: usize,
    /// MCAP: the command topic (TwistStamped or Twist), when the file has several.
    #[arg(long, value_name = "TOPIC")]
    cmd_vel: Option<String>,
    /// MCAP: the odometry topic (nav_msgs/msg/Odometry), when the file has several.
    #[arg(long, value_name = "TOPIC")]
    odom: Option<String>,
    /// Name of the `[robots.NAME]` block.
    #[arg(long, default_value = "identified")]
    name: String,
    /// Write robot.toml, identify.json and identify.svg/.png here.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
}

/// The checked configuration.
#[derive(Debug)]
struct Config {
    log: PathBuf,
    model: Option<Model>,
    agent: usize,
    /// `Some` for an MCAP log.
    bag: Option<BagOptions>,
    name: String,
    out: Option<PathBuf>,
}

impl Config {
    fn from_args(a: &IdentifyArgs) -> Result<Config> {
        anyhow::ensure!(
            a.agent >= 1,
            "--agent must be ≥ 1 (agents are numbered from 1)"
        );
        anyhow::ensure!(
            !a.name.is_empty() && !a.name.contains(['\n', '"', ']']),
            "--name `{}` cannot name a [robots.NAME] table",
            a.name
        );
        let model = a.model.map(|m| match m {
            ModelArg::Torque => Model::Torque,
            ModelArg::Velocity => Model::Velocity,
        });
        let is_mcap = a.log.extension().is_some_and(|e| e == "mcap");
        anyhow::ensure!(
            is_mcap || (a.cmd_vel.is_none() && a.odom.is_none()),
            "--cmd-vel and --odom choose topics of an MCAP log; {} is not one",
            a.log.display()
        );
        Ok(Config {
            log: a.log.clone(),
            model,
            agent: a.agent,
            bag: is_mcap.then(|| BagOptions {
                agent: a.agent,
                model,
                cmd_vel: a.cmd_vel.clone(),
                odom: a.odom.clone(),
            }),
            name: a.name.clone(),
            out: a.out.clone(),
        })
    }
}

/// Runs `echelon identify`.
pub(crate) fn identify(a: &IdentifyArgs) -> Result<()> {
    let c = Config::from_args(a)?;
    let log = match &c.bag {
        Some(opts) => echelon_mcap::bag::read_log(&c.log, opts)?,
        None => Log::read_run(&c.log, c.agent)?,
    };
    let model = match c.model.or_else(|| log.detect()) {
        Some(m) => m,
        None => anyhow::bail!(
            "{}: missing columns: neither u1, u2 (torque model) nor v_applied, omega_applied / v_cmd, omega_cmd (velocity model) for agent {}",
            log.source,
            c.agent
        ),
    };
    let id = identify::identify(&log, model)?;
    let block = id.robot_toml(&c.name);
    if let Some(dir) = &c.out {
        write(dir, &id, &block)?;
    }
    print(&id, &block)
}

fn print(id: &Identified, block: &str) -> Result<()> {
    outln!(
        "identify: {} model, agent {} of {}: {} samples over {:.3} s",
        id.model,
        id.agent,
        id.source,
        id.samples,
        id.duration
    )?;
    for ax in &id.axes {
        outln!(
            "  {} axis: residual RMS {:.3e}, max {:.3e}{}",
            ax.axis,
            ax.residual_rms,
            ax.residual_max,
            if ax.identifiable {
                ""
            } else {
                " (not identifiable)"
            }
        )?;
    }
    for w in &id.warnings {
        outln!("  warning: {w}")?;
    }
    outln!("")?;
    outln!("{}", block.trim_end())?;
    Ok(())
}

fn write(dir: &Path, id: &Identified, block: &str) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join("robot.toml");
    std::fs::write(&path, block).with_context(|| format!("writing {}", path.display()))?;
    let path = dir.join("identify.json");
    std::fs::write(&path, serde_json::to_string_pretty(id)? + "\n")
        .with_context(|| format!("writing {}", path.display()))?;
    figure(id)
        .save(dir, "identify")
        .with_context(|| format!("writing the figure into {}", dir.display()))?;
    Ok(())
}

/// Measured against model-predicted `v` and `ω` (an axis that was not
/// identified shows the measurement only).
fn figure(id: &Identified) -> Figure {
    let p = &id.prediction;
    let panel = |quantity: &str, unit: &str, measured: &[f64], model: &[f64]| {
        let mut panel = Panel::new(Axis::new("t", "s"), Axis::new(quantity, unit));
        let pts = |y: &[f64]| -> Vec<(f64, f64)> {
            p.t.iter()
                .zip(y)
                .filter(|(_, y)| y.is_finite())
                .map(|(t, y)| (*t, *y))
                .collect()
        };
        panel.line("measured", pts(measured), Stroke::series(0));
        let predicted = pts(model);
        if !predicted.is_empty() {
            panel.line("model", predicted, Stroke::series(1));
        }
        panel
    };
    Figure::new(
        &format!(
            "{} model of agent {}: measured vs predicted",
            id.model, id.agent
        ),
        1200,
        800,
    )
    .with_columns(1)
    .with_panel(panel("v", "m/s", &p.v, &p.v_model))
    .with_panel(panel("ω", "rad/s", &p.omega, &p.omega_model))
}
