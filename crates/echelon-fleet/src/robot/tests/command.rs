//! The fleet command: a stop obeyed at once and latched until a later
//! resume, a stop heard before the start.

use super::*;

/// A command from the operator, encoded; a resume signed with the tests'
/// operator token, which the robots hold.
fn command(order: crate::command::Order, seq: u64) -> Vec<u8> {
    match order {
        crate::command::Order::Resume => crate::testing::resume(seq, "operator", "test").encode(),
        crate::command::Order::Stop => {
            crate::command::FleetCommand::new(order, seq, "operator", "test").encode()
        }
    }
}

/// Drives `r` from local time `from` to `to`: the reference every 20 ms,
/// a tick whenever one is due; the states published and, after each tick,
/// the command its plant holds.
fn drive(
    r: &mut Robot<Flaky>,
    reference: &Reference,
    from: f64,
    to: f64,
) -> Vec<(RobotState, Input)> {
    let mut buf = Vec::new();
    let mut out = Vec::new();
    let mut t = from;
    while t < to {
        let k = (t / 0.02).round();
        if (t - k * 0.02).abs() < 1e-9 {
            reference_message(&mut buf, k as u64, t, reference);
            r.on_message(&buf, t);
        }
        if r.is_due(t)
            && let Some((_, st)) = r.tick(t).publish
        {
            out.push((st, r.plant().commanded));
        }
        t = ((t + 0.005) * 1e6).round() / 1e6;
    }
    out
}

/// A fleet stop commands zero the moment it is handed over (before the
/// next tick), and on every tick after; the states say `stopped`; a
/// resume numbered at or below the stop is ignored, a later one lets the
/// law run again from where the robot is (no jump in its state); garbage
/// on the command key is counted and refused.
#[test]
fn a_fleet_stop_is_obeyed_at_once_and_held_until_a_later_resume() {
    use crate::command::Order;
    let s = scenario(EXTRAPOLATE);
    let reference = reference(&s);
    let mut r = commanded_robot(&s);
    let period = r.config().period;
    let running = drive(&mut r, &reference, 0.0, 5.0);
    assert!(
        running
            .iter()
            .all(|(st, _)| st.link == LinkStatus::Tracking)
    );
    assert_ne!(r.plant().commanded, Input::default());
    assert_eq!(r.on_command(b"garbage"), crate::command::Change::Unchanged);
    assert!(!r.is_stopped());

    let stop_at = r.last().t;
    r.on_command(&command(Order::Stop, 1));
    assert!(r.is_stopped());
    assert_eq!(r.plant().commanded, Input::default(), "zero at once");
    let stopped = drive(&mut r, &reference, 5.0, 7.0);
    // Every control period a state, `stopped`, and zero held.
    assert!(
        stopped.len() as f64 >= 2.0 / period - 2.0,
        "{}",
        stopped.len()
    );
    for (st, cmd) in &stopped {
        assert_eq!(st.link, LinkStatus::Stopped, "{st:?}");
        assert_eq!(*cmd, Input::default());
        assert_eq!(st.u, Input::default());
    }
    assert!(stopped[0].0.t - stop_at <= period + 1e-9);
    r.on_command(&command(Order::Resume, 1));
    assert!(r.is_stopped(), "a resume not after the stop is ignored");
    let before = *r.last();
    r.on_command(&command(Order::Resume, 2));
    assert!(!r.is_stopped());
    let resumed = drive(&mut r, &reference, 7.0, 7.2);
    let (first, cmd) = resumed[0];
    assert_eq!(first.link, LinkStatus::Tracking);
    assert_ne!(cmd, Input::default());
    assert!(dist(&first.state, &before.state) < 0.01, "no jump");
    let c = r.command_counts();
    assert_eq!(
        (c.received, c.stops, c.resumes, c.ignored, c.refused),
        (4, 1, 1, 1, 1)
    );
    assert_eq!(r.report().commands, c);
}

/// A stop learnt from another process's latch answer before the robot
/// heard its leader latches: it stands still (waiting, then `stopped` once
/// its clock follows the leader) until a resume numbered after that stop.
#[test]
fn a_stop_heard_before_start_latches() {
    use crate::command::{FleetCommand, Latched, Order};
    let s = scenario(EXTRAPOLATE);
    let reference = reference(&s);
    let mut r = commanded_robot(&s);
    let answer = Latched {
        stopped: true,
        command: Some(FleetCommand::new(Order::Stop, 4, "operator", "")),
        hazards: HazardSet::EMPTY,
        refused: None,
    };
    r.on_latch_answer(&answer.encode());
    assert!(r.is_stopped());
    let stopped = drive(&mut r, &reference, 0.0, 2.0);
    assert!(stopped.len() > 100);
    assert!(
        stopped
            .iter()
            .all(|(st, cmd)| st.link == LinkStatus::Stopped && *cmd == Input::default())
    );
    assert_eq!(r.last().state, r.config().spec.start());
    r.on_command(&command(Order::Resume, 4));
    assert!(r.is_stopped());
    r.on_command(&command(Order::Resume, 5));
    let moving = drive(&mut r, &reference, 2.0, 3.0);
    assert!(moving.iter().all(|(st, _)| st.link == LinkStatus::Tracking));
    assert!(dist(&r.last().state, &r.config().spec.start()) > 0.01);
}

/// A resume without a valid proof of the operator token (unsigned, signed
/// with another token, or any resume to a robot without a token) leaves a
/// stopped robot stopped, commanding zero; it is counted and named in the
/// robot's latch answer, which `fleet resume` reports.
#[test]
fn a_resume_without_the_operator_token_leaves_the_robot_stopped() {
    use crate::command::{FleetCommand, Order};
    use crate::token::OperatorToken;
    let s = scenario(EXTRAPOLATE);
    let reference = reference(&s);
    let other =
        OperatorToken::parse("0123456789abcdef0123456789abcdef").unwrap_or_else(|e| panic!("{e}"));
    let unsigned = FleetCommand::new(Order::Resume, 2, "operator", "go");
    let forged = FleetCommand::new(Order::Resume, 3, "operator", "go").signed(&other);
    for (token, resume, why) in [
        (true, &unsigned, "no valid operator token"),
        (true, &forged, "no valid operator token"),
        (
            false,
            &crate::testing::resume(4, "operator", "go"),
            "this process has no operator token",
        ),
    ] {
        let config = crate::testing::robot_config(&s, 1, FaultSpec::default());
        let config = RobotConfig {
            operator_token: token.then(crate::testing::operator_token),
            ..config
        };
        let plant = Flaky {
            inner: SimulatedDrive::of(&config.spec, 0.0, PLANT_STEP),
            lost: false,
            commanded: Input::default(),
        };
        let mut r = Robot::new(config, plant, 1);
        drive(&mut r, &reference, 0.0, 1.0);
        r.on_command(&command(Order::Stop, 1));
        assert!(r.is_stopped());
        assert_eq!(
            r.on_command(&resume.encode()),
            crate::command::Change::Unchanged
        );
        assert!(r.is_stopped(), "{resume:?}");
        let held = drive(&mut r, &reference, 1.0, 2.0);
        assert!(
            held.iter()
                .all(|(st, cmd)| st.link == LinkStatus::Stopped && *cmd == Input::default())
        );
        assert_eq!(r.command_counts().unauthorized, 1);
        let refused = r.latched().refused.unwrap_or_else(|| panic!("named"));
        assert!(refused.is_of(resume));
        assert_eq!(
            refused.to_string(),
            format!("resume {} by operator: {why}", resume.seq)
        );
        assert_eq!(r.report().commands.unauthorized, 1);
    }
}
