//! Every network input of a fleet process, mutated and fed to its decoder
//! and its consumer (DEVELOPERS.md: "Network input is counted and refused,
//! never a crash"). The style of `echelon/tests/fuzz_scenarios.rs`: a
//! corpus of real messages (our encoders', and ROS 2 Jazzy's own bytes from
//! rclpy, `tests/fixtures/rclpy_messages.txt`), every single mutation of
//! each (truncated at every length, every byte flipped, set to 0x00, 0xff,
//! 0x80, every aligned f64 slot set to NaN, ±∞ and huge values, every
//! aligned u32 (a length, a count) set huge, bytes appended), then random
//! combinations from a fixed seed (CI runs the same sample). Whatever the
//! input:
//!
//! - no decoder and no consumer panics (`catch_unwind`; a failure prints
//!   the input's hex);
//! - a refusal is an `Err` and its consumer counts it, once, in the
//!   counter of its reason, and nothing else changes (the robot's next
//!   command is the one it would have sent without the input);
//! - an accepted message holds finite values only, and its consumer still
//!   commands and publishes finite values; an accepted fleet wire message
//!   is exactly the encoding of what it decoded to (no byte ignored: a
//!   reserved byte or an unknown drive flag is refused); an accepted
//!   odometry or fix has a unit quaternion (within tf2's tolerance; a zero
//!   quaternion never becomes a heading), and an accepted fix leaves the
//!   robot within its divergence guard's position bound;
//! - valid messages round-trip exactly.
//!
//! Inputs: the fleet wire messages ([`wire::decode`]) as the robot takes
//! them on its leader stream and its neighbours' (safety) and as the
//! collector logs them; the fleet commands and latch answers; the ROS 2
//! CDR messages (`Twist`, `TwistStamped`, `Odometry`, `PoseStamped`,
//! `PoseWithCovarianceStamped`) as the ROS 2 drive (odometry), the fixes
//! and the simulated base (`cmd_vel`, with its 33-byte attachment) take
//! them and the collector records them; rmw_zenoh keys and the fleet's keys.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::panic::{AssertUnwindSafe, catch_unwind};

use echelon::agent::{Actuation, Command, Drive};
use echelon::base::{VelocityBase, VelocityBaseSpec, VelocityCommand, VelocityRobot};
use echelon::control::LeaderMotion;
use echelon::model::{Input, Pose, State, Torques};
use echelon::odometry::{ErrorModel, FixSchedule, FixSpec, Fusion};
use echelon::sample::{AgentSample, VelocitySample};
use echelon::scenario::schema::FixMessage;
use echelon::scenario::{FixSource, Overrides, Ros2Link, Scenario};
use echelon_fleet::collector::{Channel, Collector, RecordSink, Stamp};
use echelon_fleet::command::{FleetCommand, Latched, Order};
use echelon_fleet::faults::FaultSpec;
use echelon_fleet::keys::{KeyKind, Keys};
use echelon_fleet::plant::{Plant, SimulatedDrive};
use echelon_fleet::robot::{Robot, RobotConfig, sample_of};
use echelon_fleet::ros2::drive::{CmdSink, Ros2Counters, Ros2Drive, encode_cmd_vel};
use echelon_fleet::ros2::fixes::{FixInput, OdometryModel, fix_type};
use echelon_fleet::ros2::hazard::HazardSet;
use echelon_fleet::ros2::record::RosTopic;
use echelon_fleet::ros2::sim_base::{BaseCounters, SimBase};
use echelon_fleet::wire::{
    self, DecodeError, Header, LinkStatus, Message, OdometryState, Reference, RobotState,
};
use echelon_mcap::scene::ScenePose;
use echelon_ros2::attachment::{ATTACHMENT_LEN, Attachment, GID_LEN};
use echelon_ros2::cdr::ENCAPSULATION_CDR_LE;
use echelon_ros2::keys::{check_topic_key, topic_key};
use echelon_ros2::msgs::{
    self, Odometry, PoseStamped, PoseWithCovarianceStamped, RosMessage, Time, Twist, TwistStamped,
};
use echelon_ros2::names::fully_qualified_topic;
use echelon_ros2::{KeyScheme, MessageType};
use proptest::prelude::*;
use proptest::test_runner::{Config as ProptestConfig, RngSeed};

// ---------------------------------------------------------------------------
// The mutations.

/// What an aligned f64 slot is set to.
const F64S: [f64; 11] = [
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::MAX,
    -f64::MAX,
    1e300,
    -1e300,
    1e154,
    1e15,
    5e-324,
    -0.0,
];

/// What an aligned u32 slot (a string length, a count, an agent) is set to.
const U32S: [u32; 7] = [0, 1, 4096, 4097, 0x7fff_ffff, 0x8000_0000, u32::MAX];

/// A mutated input and what was done to it.
type Mutant = (String, Vec<u8>);

/// Every single mutation of `valid`, named. Slots are aligned from byte
/// `base` (0: the fleet wire, whose fields are aligned to their size; 4:
/// CDR, aligned after its encapsulation header).
fn single_mutations(valid: &[u8], base: usize) -> Vec<Mutant> {
    let mut out = Vec::new();
    for n in 0..valid.len() {
        out.push((format!("truncated to {n}"), valid[..n].to_vec()));
    }
    for i in 0..valid.len() {
        for (name, f) in [
            ("flipped", (|b: u8| !b) as fn(u8) -> u8),
            ("low bit flipped", |b| b ^ 1),
            ("set to 00", |_| 0x00),
            ("set to ff", |_| 0xff),
            ("set to 80", |_| 0x80),
        ] {
            let mut m = valid.to_vec();
            m[i] = f(m[i]);
            if m != valid {
                out.push((format!("byte {i} {name}"), m));
            }
        }
    }
    // Every f64 and u32 word from `base` on, set to each special value.
    let words = F64S
        .iter()
        .map(|v| (format!("f64 {v:e}"), v.to_le_bytes().to_vec()))
        .chain(
            U32S.iter()
                .map(|v| (format!("u32 {v}"), v.to_le_bytes().to_vec())),
        );
    for (what, word) in words {
        let mut at = base;
        while at + word.len() <= valid.len() {
            let mut m = valid.to_vec();
            m[at..at + word.len()].copy_from_slice(&word);
            out.push((format!("{what} at {at}"), m));
            at += word.len();
        }
    }
    for (name, tail) in [
        ("a zero byte appended", vec![0u8]),
        ("8 ff bytes appended", vec![0xff; 8]),
        ("itself appended", valid.to_vec()),
    ] {
        let mut m = valid.to_vec();
        m.extend_from_slice(&tail);
        out.push((name.to_owned(), m));
    }
    out
}

/// Every pair of aligned f64 slots (from `base`) set huge together: finite
/// numbers whose sums and products overflow (a quaternion of two 1e308
/// components has no yaw: `atan2` of `∞ − ∞`).
fn pair_mutations(valid: &[u8], base: usize) -> Vec<Mutant> {
    let slots: Vec<usize> = (base..valid.len().saturating_sub(7)).step_by(8).collect();
    let mut out = Vec::new();
    for (k, &a) in slots.iter().enumerate() {
        for &b in &slots[k + 1..] {
            for (va, vb) in [(f64::MAX, f64::MAX), (f64::MAX, -f64::MAX), (1e200, 1e200)] {
                let mut m = valid.to_vec();
                m[a..a + 8].copy_from_slice(&va.to_le_bytes());
                m[b..b + 8].copy_from_slice(&vb.to_le_bytes());
                out.push((format!("f64s at {a}, {b} = {va:e}, {vb:e}"), m));
            }
        }
    }
    out
}

/// What a unit quaternion found in a message is scaled by: zero (an
/// uninitialised message's), within tf2's tolerance of unit length (its
/// squared norm within 10e-3 of 1) and beyond it, tiny and huge.
const QUATERNION_SCALES: [f64; 11] = [
    0.0, -0.0, 1e-200, 0.5, 0.99, 0.996, 1.004, 1.006, 2.0, 1e100, 1e200,
];

/// Every window of four aligned f64s (from `base`) holding a unit
/// quaternion (a message's orientation, found by its norm) scaled by each
/// of [`QUATERNION_SCALES`], and set to `(1, 1, 1, 1)` and `(0, 0, 0, 1e-3)`.
fn quaternion_mutations(valid: &[u8], base: usize) -> Vec<Mutant> {
    let f64_at = |b: &[u8], at: usize| f64::from_le_bytes(b[at..at + 8].try_into().expect("8"));
    let mut out = Vec::new();
    let mut at = base;
    while at + 32 <= valid.len() {
        let q: [f64; 4] = std::array::from_fn(|i| f64_at(valid, at + 8 * i));
        if (q.iter().map(|c| c * c).sum::<f64>() - 1.0).abs() < 1e-12 {
            let scaled = QUATERNION_SCALES.map(|s| q.map(|c| s * c));
            for (k, v) in scaled
                .into_iter()
                .chain([[1.0; 4], [0.0, 0.0, 0.0, 1e-3]])
                .enumerate()
            {
                let mut m = valid.to_vec();
                for (i, c) in v.iter().enumerate() {
                    m[at + 8 * i..at + 8 * i + 8].copy_from_slice(&c.to_le_bytes());
                }
                out.push((format!("quaternion at {at} #{k} = {v:?}"), m));
            }
        }
        at += 8;
    }
    assert!(!out.is_empty(), "no unit quaternion in {}", hex(valid));
    out
}

/// Whether `q` is a rotation by tf2's rule (`|x² + y² + z² + w² − 1| <
/// 10e-3`), computed here apart from `checked_yaw`.
fn tf2_takes(q: &msgs::Quaternion) -> bool {
    ((q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w) - 1.0).abs() < 10e-3
}

/// One step of a random combination.
#[derive(Debug, Clone)]
enum Op {
    Truncate(prop::sample::Index),
    SetByte(prop::sample::Index, u8),
    F64(prop::sample::Index, f64),
    U32(prop::sample::Index, u32),
    Insert(prop::sample::Index, u8),
    Remove(prop::sample::Index),
    Append(Vec<u8>),
}

fn op() -> impl Strategy<Value = Op> {
    let f64s = prop_oneof![
        prop::sample::select(F64S.to_vec()),
        any::<f64>(),
        -1e3..1e3f64,
        any::<u64>().prop_map(f64::from_bits),
    ];
    prop_oneof![
        any::<prop::sample::Index>().prop_map(Op::Truncate),
        (any::<prop::sample::Index>(), any::<u8>()).prop_map(|(i, b)| Op::SetByte(i, b)),
        (any::<prop::sample::Index>(), f64s).prop_map(|(i, v)| Op::F64(i, v)),
        (
            any::<prop::sample::Index>(),
            prop_oneof![prop::sample::select(U32S.to_vec()), any::<u32>()]
        )
            .prop_map(|(i, v)| Op::U32(i, v)),
        (any::<prop::sample::Index>(), any::<u8>()).prop_map(|(i, b)| Op::Insert(i, b)),
        any::<prop::sample::Index>().prop_map(Op::Remove),
        prop::collection::vec(any::<u8>(), 1..16).prop_map(Op::Append),
    ]
}

/// `b` with `ops` applied in turn (slots aligned from `base`).
fn apply(b: &[u8], ops: &[Op], base: usize) -> Vec<u8> {
    let mut m = b.to_vec();
    for o in ops {
        let n = m.len();
        match o {
            Op::Truncate(i) => m.truncate(i.index(n + 1)),
            Op::SetByte(i, v) if n > 0 => {
                let i = i.index(n);
                m[i] = *v;
            }
            Op::F64(i, v) if n >= base + 8 => {
                let at = base + 8 * i.index((n - base) / 8);
                m[at..at + 8].copy_from_slice(&v.to_le_bytes());
            }
            Op::U32(i, v) if n >= base + 4 => {
                let at = base + 4 * i.index((n - base) / 4);
                m[at..at + 4].copy_from_slice(&v.to_le_bytes());
            }
            Op::Insert(i, v) => m.insert(i.index(n + 1), *v),
            Op::Remove(i) if n > 0 => {
                m.remove(i.index(n));
            }
            Op::Append(tail) => m.extend_from_slice(tail),
            _ => {}
        }
    }
    m
}

fn hex(b: &[u8]) -> String {
    b.iter().fold(String::new(), |mut s, x| {
        let _ = write!(s, "{x:02x}");
        s
    })
}

fn unhex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).expect("hex"))
        .collect()
}

/// Runs `check` on `input`; a panic is a failure naming the input's hex.
fn no_panic(input: &[u8], check: impl FnOnce() -> Result<(), String>) -> Result<(), String> {
    catch_unwind(AssertUnwindSafe(check)).unwrap_or_else(|p| {
        let why = p
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| (*s).to_owned()))
            .unwrap_or_default();
        Err(format!("PANIC ({why}) on {}", hex(input)))
    })
}

/// Every single mutation of every message of `corpus` through `check`;
/// fails listing the first failures. Returns how many were checked.
fn every_single_mutation(
    what: &str,
    corpus: &[Vec<u8>],
    base: usize,
    check: impl Fn(&[u8]) -> Result<(), String>,
) -> usize {
    every_mutation(what, corpus, base, single_mutations, check)
}

/// [`every_single_mutation`], mutations made by `mutations`.
fn every_mutation(
    what: &str,
    corpus: &[Vec<u8>],
    base: usize,
    mutations: fn(&[u8], usize) -> Vec<Mutant>,
    check: impl Fn(&[u8]) -> Result<(), String>,
) -> usize {
    let mut failures = Vec::new();
    let mut count = 0;
    for (k, valid) in corpus.iter().enumerate() {
        for (name, m) in mutations(valid, base) {
            count += 1;
            if let Err(e) = no_panic(&m, || check(&m)) {
                failures.push(format!("{what} #{k}, {name}: {e}\n  input {}", hex(&m)));
            }
        }
    }
    none_failed(&failures, &format!("{count} mutations of {what}"));
    count
}

/// No failure among `of` (up to 12 of them shown).
fn none_failed(failures: &[String], of: &str) {
    assert!(
        failures.is_empty(),
        "{} of {of} failed; the first:\n{}",
        failures.len(),
        failures[..failures.len().min(12)].join("\n")
    );
}

/// Proptest with a fixed seed (CI runs the same sample) and no files.
fn fixed(cases: u32, seed: u64) -> ProptestConfig {
    ProptestConfig {
        cases,
        rng_seed: RngSeed::Fixed(seed),
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

fn finite(what: &str, values: &[f64]) -> Result<(), String> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(format!("{what}: value {i} is {} in {values:?}", values[i])),
        None => Ok(()),
    }
}

// ---------------------------------------------------------------------------
// The fleet wire.

fn motion(t: f64) -> LeaderMotion {
    // The fast circle's reference (0.2 m/s, 0.2 rad/s) at time t.
    let (s, c) = (0.2 * t).sin_cos();
    LeaderMotion {
        p: [s, 1.0 - c],
        dp: [0.2 * c, 0.2 * s],
        ddp: [-0.04 * s, 0.04 * c],
    }
}

fn reference_at(t: f64, seq: u64) -> Vec<u8> {
    let mut buf = Vec::new();
    let r = Reference {
        t,
        motion: motion(t),
        speed: 0.2,
        turn_rate: 0.2,
    };
    wire::encode_reference(&mut buf, Header { source: 11, seq }, &r);
    buf
}

fn state_of(agent: u32, t: f64, velocity: bool, odometry: bool) -> RobotState {
    let m = motion(t);
    RobotState {
        t,
        agent,
        link: LinkStatus::Tracking,
        state: State {
            x: m.p[0] - 0.3,
            y: m.p[1] - 0.35,
            theta: 0.2 * t,
            v: 0.2,
            omega: 0.2,
        },
        dv: 0.01,
        domega: -0.02,
        e: [0.05, -0.03],
        z: [0.01, 0.02],
        u: Input { u1: 0.3, u2: -0.1 },
        tau: Torques {
            right: 0.4,
            left: 0.35,
        },
        leader: m,
        velocity: velocity.then_some(VelocitySample {
            v_cmd: 0.21,
            omega_cmd: 0.19,
            v_applied: 0.2,
            omega_applied: 0.2,
            sat: true,
        }),
        sigma: 0.02,
        odometry: odometry.then_some(OdometryState {
            raw: [0.1, -0.2, 0.3],
            age: 0.01,
            fix_age: Some(0.5),
        }),
    }
}

fn encode(m: &Message) -> Vec<u8> {
    let mut buf = Vec::new();
    match m {
        Message::Reference(h, r) => wire::encode_reference(&mut buf, *h, r),
        Message::State(h, s) => wire::encode_state(&mut buf, *h, s),
    }
    buf
}

fn state_message(agent: u32, t: f64, seq: u64, velocity: bool, odometry: bool) -> Vec<u8> {
    encode(&Message::State(
        Header { source: 21, seq },
        state_of(agent, t, velocity, odometry),
    ))
}

/// References and states of every layout (torque, velocity, with odometry).
fn wire_corpus() -> Vec<Vec<u8>> {
    let mut states = vec![reference_at(1.0, 3)];
    for (v, o) in [(false, false), (true, false), (true, true), (false, true)] {
        states.push(state_message(1, 1.0, 3, v, o));
    }
    let mut no_fix = state_of(1, 1.0, true, true);
    no_fix.odometry = Some(OdometryState {
        fix_age: None,
        ..OdometryState::default()
    });
    states.push(encode(&Message::State(
        Header { source: 5, seq: 9 },
        no_fix,
    )));
    states
}

/// Every f64 an accepted message carries is finite, its numbers in their
/// ranges, and it re-encodes to a message that decodes to itself.
fn check_accepted_wire(m: &Message) -> Result<(), String> {
    let bytes = encode(m);
    let floats: Vec<f64> = match m {
        Message::Reference(..) => (16..bytes.len()).step_by(8).collect::<Vec<_>>(),
        Message::State(..) => std::iter::once(16)
            .chain((32..bytes.len()).step_by(8))
            .collect(),
    }
    .into_iter()
    .map(|at| f64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes")))
    .collect();
    finite("accepted wire message", &floats)?;
    if let Message::State(_, s) = m {
        if s.agent == 0 || s.sigma < 0.0 {
            return Err(format!("accepted a state out of range: {s:?}"));
        }
        if let Some(o) = s.odometry
            && (o.age < 0.0 || o.fix_age.is_some_and(|a| a < 0.0))
        {
            return Err(format!("accepted a negative odometry age: {o:?}"));
        }
    }
    match wire::decode(&bytes) {
        Ok(back) if back == *m => Ok(()),
        other => Err(format!("re-encoded {m:?} decodes to {other:?}")),
    }
}

/// What the decoder accepts is finite, in range and exactly the encoding
/// of what it decoded to: every byte read, none ignored (a state's
/// reserved bytes, its drive flags, a zero's sign).
fn check_wire(b: &[u8]) -> Result<(), String> {
    match wire::decode(b) {
        Ok(m) => {
            check_accepted_wire(&m)?;
            if encode(&m) != b {
                return Err(format!("accepted {m:?}, which encodes otherwise"));
            }
            Ok(())
        }
        Err(_) => Ok(()),
    }
}

#[test]
fn valid_wire_messages_round_trip_exactly() {
    for b in wire_corpus() {
        let m = wire::decode(&b).unwrap_or_else(|e| panic!("{e}: {}", hex(&b)));
        assert_eq!(encode(&m), b, "{m:?}");
    }
}

#[test]
fn every_single_mutation_of_a_wire_message_is_refused_or_finite() {
    let n = every_single_mutation("wire", &wire_corpus(), 0, check_wire);
    eprintln!("{n} wire mutations checked");
}

/// Every value of every reserved byte of a state, and every drive flag bit
/// this version does not define: malformed to the decoder, counted as such
/// by a robot on its leader stream and by a robot's safety filter, logged
/// on `/rejected` by the collector; the robot's commands as without it.
#[test]
fn a_state_with_a_reserved_byte_or_an_unknown_flag_is_refused_everywhere() {
    let s = fleet_scenario(true);
    let base = synced_robot(&s, 2, &state_message(1, 1.0, 0, false, false));
    let expected = run_ticks(&mut base.clone(), 0.02, 3).expect("the unmutated robot");
    let keys = Keys::new("fuzz");
    let mut mutants = Vec::new();
    for (v, o) in [(false, false), (true, false), (true, true)] {
        let valid = state_message(1, 1.02, 1, v, o);
        for at in wire::HEADER_LEN + 5..wire::HEADER_LEN + 8 {
            for byte in 1..=255u8 {
                let mut m = valid.clone();
                m[at] = byte;
                mutants.push(m);
            }
        }
        for bit in 4..8 {
            let mut m = valid.clone();
            m[wire::HEADER_LEN + 4] |= 1 << bit;
            mutants.push(m);
        }
    }
    for m in &mutants {
        assert!(
            matches!(wire::decode(m), Err(DecodeError::Malformed(_))),
            "{}",
            hex(m)
        );
        check_leader_stream(&base, &expected, m).unwrap_or_else(|e| panic!("{e}: {}", hex(m)));
        let mut r = base.clone();
        let before = r.counters().malformed;
        r.on_message(m, 0.02);
        assert_eq!(r.counters().malformed, before + 1, "{}", hex(m));
        let refused = r.safety_counts().expect("a safety filter").refused;
        r.on_neighbour(wire::decode(m), 0.02);
        assert_eq!(
            r.safety_counts().expect("a safety filter").refused,
            refused + 1
        );
        let mut c = Collector::new(keys.clone());
        let mut sink = Counting::default();
        c.on_message(&keys.state(1), m, 1_000, &mut sink)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(rejected(&c), 1, "{}", hex(m));
    }
    assert_eq!(mutants.len(), 3 * (3 * 255 + 4));
}

// ---------------------------------------------------------------------------
// The robot: leader stream, neighbours, commands.

/// A simulated drive that records every command the robot sends it.
#[derive(Debug, Clone)]
struct Recorded {
    drive: SimulatedDrive,
    commands: Vec<Command>,
}

impl Plant for Recorded {
    fn state(&self) -> Option<State> {
        self.drive.state()
    }
    fn advance(&mut self, t: f64) {
        self.drive.advance(t);
    }
    fn command(&mut self, cmd: Command) -> Actuation {
        self.commands.push(cmd);
        self.drive.command(cmd)
    }
    fn stop(&mut self) {
        self.commands.push(Command::Torque(Input::default()));
        self.drive.stop();
    }
    fn accelerations(&self) -> (f64, f64) {
        self.drive.accelerations()
    }
    fn set_time(&mut self, t: f64) {
        self.drive.set_time(t);
    }
}

fn command_values(c: &Command) -> Vec<f64> {
    match c {
        Command::Torque(u) => vec![u.u1, u.u2],
        Command::Velocity(v) => vec![v.v, v.omega],
        #[allow(unreachable_patterns)]
        _ => Vec::new(),
    }
}

/// The CLI's fast circle (two robots, robot 2 behind robot 1), with a
/// safety filter when `safety`.
fn fleet_scenario(safety: bool) -> Scenario {
    let mut src =
        include_str!("../../echelon-cli/tests/fleet/fast-circle.toml").replace("\r\n", "\n");
    if safety {
        src = src.replace(
            "[fleet]",
            "[safety]\nradius = 0.2\ngain = 1.0\nrange = 1.5\n\n[fleet]",
        );
    }
    Scenario::parse(&src, "fuzz.toml", None).unwrap_or_else(|e| panic!("{e}"))
}

fn robot_config(s: &Scenario, agent: u32) -> RobotConfig {
    let fleet = s.fleet().unwrap_or_else(|e| panic!("{e}"));
    let plan = s
        .build(&Overrides::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .plan;
    RobotConfig::from_plan(&plan, &fleet, agent, FaultSpec::default(), None)
        .unwrap_or_else(|e| panic!("{e}"))
}

/// The operator token the fuzzed robots hold.
fn operator_token() -> echelon_fleet::token::OperatorToken {
    echelon_fleet::token::OperatorToken::parse("f0220000000000000000000000000002")
        .unwrap_or_else(|e| panic!("{e}"))
}

fn robot(config: RobotConfig) -> Robot<Recorded> {
    let drive = SimulatedDrive::of(&config.spec, 0.0, echelon_fleet::robot::PLANT_STEP);
    let plant = Recorded {
        drive,
        commands: Vec::new(),
    };
    let config = RobotConfig {
        operator_token: Some(operator_token()),
        ..config
    };
    Robot::new(config, plant, 99)
}

/// Robot `agent` of the fast circle, synced on its leader's stream
/// (`first`, at local time 0) and ticked once, its commands forgotten.
fn synced_robot(s: &Scenario, agent: u32, first: &[u8]) -> Robot<Recorded> {
    let mut r = robot(robot_config(s, agent));
    r.on_message(first, 0.0);
    assert_eq!(r.counters().malformed, 0);
    r.tick(0.0);
    r.plant_mut().commands.clear();
    r
}

/// What a robot does over the next `n` ticks from local time `from`: the
/// commands it sends and the states it publishes, each checked finite and
/// decodable.
fn run_ticks(r: &mut Robot<Recorded>, from: f64, n: usize) -> Result<Vec<Command>, String> {
    let period = r.config().period;
    for k in 0..n {
        let now = from + k as f64 * period;
        if !r.is_due(now) {
            continue;
        }
        let tick = r.tick(now);
        if let Some((h, s)) = tick.publish {
            let bytes = encode(&Message::State(h, s));
            match wire::decode(&bytes) {
                Ok(m) => check_accepted_wire(&m)?,
                Err(e) => return Err(format!("the robot published a state refused ({e}): {s:?}")),
            }
        }
    }
    let commands = std::mem::take(&mut r.plant_mut().commands);
    for c in &commands {
        finite("a command", &command_values(c))?;
    }
    Ok(commands)
}

/// Feeds `bytes` to `base`'s clone on its leader stream: a refusal is
/// counted once in its reason and changes nothing else (the same
/// commands next); an accepted sample still gives finite commands.
fn check_leader_stream(
    base: &Robot<Recorded>,
    expected: &[Command],
    bytes: &[u8],
) -> Result<(), String> {
    let mut r = base.clone();
    let before = *r.counters();
    let pending = r.pending();
    r.on_message(bytes, 0.02);
    let after = *r.counters();
    if after.received != before.received + 1 {
        return Err("not counted as received".into());
    }
    let decoded = wire::decode(bytes);
    let mut want = before;
    want.received += 1;
    let refused = match decoded {
        Err(DecodeError::Malformed(_)) => {
            want.malformed += 1;
            true
        }
        Err(DecodeError::WrongVersion(_)) => {
            want.wrong_version += 1;
            true
        }
        Ok(m) if r.pending() == pending => {
            match sample_of(&m, r.config().spec.leader()) {
                // Of its stream, but no robot could follow it.
                Some((_, s)) if !s.within(&r.config().bounds) => want.malformed += 1,
                // Not of its leader's stream (another kind or agent, or a
                // waiting robot's state).
                _ => want.foreign += 1,
            }
            true
        }
        Ok(_) => false,
    };
    if refused {
        if after != want {
            return Err(format!(
                "refused ({decoded:?}) but counted {after:?}, expected {want:?}"
            ));
        }
        let commands = run_ticks(&mut r, 0.02, 3)?;
        if commands != expected {
            return Err(format!(
                "refused ({decoded:?}) but it changed the commands: {commands:?} vs {expected:?}"
            ));
        }
        return Ok(());
    }
    let m = decoded.map_err(|e| e.to_string())?;
    check_accepted_wire(&m)?;
    run_ticks(&mut r, 0.02, 3)?;
    // A leader kilometres away (a flipped exponent) is a valid message: the
    // torque law drives the robot past the divergence guard, which stops it
    // (zero commanded, said, never a NaN). Counted, not a failure.
    if r.diverged().is_some() {
        DIVERGED.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    }
    Ok(())
}

/// Accepted leader samples that sent the robot past its divergence guard.
static DIVERGED: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

#[test]
fn every_single_mutation_of_a_leader_message_is_counted_or_followed_finitely() {
    let s = fleet_scenario(false);
    // Robot 1 follows the reference; robot 2 follows robot 1's state.
    for (agent, first, corpus) in [
        (1, reference_at(1.0, 0), wire_corpus()),
        (
            2,
            state_message(1, 1.0, 0, false, false),
            vec![
                state_message(1, 1.02, 1, false, false),
                state_message(1, 1.02, 1, true, true),
                reference_at(1.02, 1),
            ],
        ),
    ] {
        let base = synced_robot(&s, agent, &first);
        let expected = run_ticks(&mut base.clone(), 0.02, 3).expect("the unmutated robot");
        assert!(!expected.is_empty(), "robot {agent} sends commands");
        let n = every_single_mutation(&format!("robot {agent}'s leader stream"), &corpus, 0, |b| {
            check_leader_stream(&base, &expected, b)
        });
        eprintln!(
            "robot {agent}: {n} leader-stream mutations checked; {} accepted ones diverged so far",
            DIVERGED.load(std::sync::atomic::Ordering::Relaxed)
        );
    }
}

/// A robot with a safety filter takes every robot's state: a refusal is
/// counted in its safety counters; whatever it takes, its commands stay
/// finite.
#[test]
fn every_single_mutation_of_a_neighbour_state_is_counted_or_avoided_finitely() {
    let s = fleet_scenario(true);
    let mut base = synced_robot(&s, 2, &state_message(1, 1.0, 0, false, false));
    assert!(base.has_safety());
    let _ = run_ticks(&mut base, 0.0, 1);
    let corpus = vec![
        state_message(1, 1.02, 1, false, false),
        state_message(1, 1.02, 1, true, true),
    ];
    let n = every_single_mutation("a neighbour's state", &corpus, 0, |b| {
        let mut r = base.clone();
        let before = r.safety_counts().expect("a safety filter").refused;
        let msg = wire::decode(b);
        let counted = !matches!(msg, Ok(Message::State(..)));
        r.on_neighbour(msg, 0.02);
        let after = r.safety_counts().expect("a safety filter").refused;
        if counted && after != before + 1 {
            return Err(format!("refused but counted {after} (was {before})"));
        }
        if after > before + 1 {
            return Err(format!("counted {} refusals", after - before));
        }
        run_ticks(&mut r, 0.02, 3).map(|_| ())
    });
    eprintln!("{n} neighbour mutations checked");
}

/// JSON texts with each scalar value replaced and bytes mutated.
fn json_mutations(valid: &[u8]) -> Vec<Mutant> {
    const VALUES: &[&str] = &[
        "-1",
        "0",
        "1.5",
        "1e400",
        "-1e400",
        "18446744073709551616",
        "18446744073709551615",
        "4294967296",
        "null",
        "true",
        "\"\"",
        "\"stop\"",
        "\"resume\"",
        "\"\\u0000\"",
        "\"\\ud800\"",
        "[]",
        "{}",
    ];
    let text = std::str::from_utf8(valid).expect("JSON is UTF-8");
    let mut out = single_mutations(valid, 0);
    // Each value: after a ':' up to the next ',' or '}' at the same depth
    // (the corpus nests one object at most and has no ',' in strings).
    let starts: Vec<usize> = text.match_indices(':').map(|(i, _)| i + 1).collect();
    for &start in &starts {
        let end = text[start..]
            .find([',', '}'])
            .map_or(text.len(), |e| start + e);
        if text[start..].starts_with('{') {
            continue;
        }
        let long = format!("\"{}\"", "é".repeat(300));
        let deep = format!("{}{}", "[".repeat(4000), "]".repeat(4000));
        for v in VALUES.iter().copied().chain([long.as_str(), deep.as_str()]) {
            let m = format!("{}{v}{}", &text[..start], &text[end..]);
            let shown: String = v.chars().take(12).collect();
            out.push((format!("value at {start} = {shown}"), m.into_bytes()));
        }
    }
    let added = text.replacen('{', "{\"extra\":1,", 1);
    out.push(("a key added".into(), added.into_bytes()));
    out.push(("twice".into(), format!("{text}{text}").into_bytes()));
    out
}

#[test]
fn every_mutation_of_a_fleet_command_is_counted_or_obeyed() {
    let s = fleet_scenario(false);
    let base = synced_robot(&s, 1, &reference_at(1.0, 0));
    let corpus = [
        FleetCommand::new(Order::Stop, 3, "operator", "test").encode(),
        FleetCommand::new(Order::Resume, 7, "leader", "")
            .signed(&operator_token())
            .encode(),
    ];
    let mut failures = Vec::new();
    let mut count = 0;
    for valid in &corpus {
        let decoded = FleetCommand::decode(valid).expect("a valid command");
        assert_eq!(FleetCommand::decode(&decoded.encode()), Ok(decoded));
        for (name, m) in json_mutations(valid) {
            count += 1;
            let check = || {
                let mut r = base.clone();
                let before = r.command_counts();
                let latched = r.latched();
                r.on_command(&m);
                let after = r.command_counts();
                if after.received != before.received + 1 {
                    return Err("not counted as received".to_owned());
                }
                match FleetCommand::decode(&m) {
                    Err(_) => {
                        let mut want = before;
                        want.received += 1;
                        want.refused += 1;
                        if after != want || r.latched() != latched {
                            return Err(format!("refused but counted {after:?}"));
                        }
                    }
                    Ok(c) => {
                        if after.refused != before.refused {
                            return Err(format!("accepted {c:?} but counted refused"));
                        }
                        if c.by.is_empty() {
                            return Err(format!("accepted {c:?} without a sender"));
                        }
                        // A resume is obeyed only with a valid proof: any
                        // other is counted as unauthorized, and only it.
                        let refused = after.unauthorized - before.unauthorized;
                        let forged = c.order == Order::Resume && !c.verified_by(&operator_token());
                        if refused != u64::from(forged) {
                            return Err(format!("{c:?}: {refused} counted unauthorized"));
                        }
                    }
                }
                let stopped = r.is_stopped();
                let commands = run_ticks(&mut r, 0.02, 3)?;
                if stopped && commands.iter().any(|c| command_values(c) != [0.0, 0.0]) {
                    return Err(format!("stopped but commanded {commands:?}"));
                }
                Ok(())
            };
            if let Err(e) = no_panic(&m, check) {
                failures.push(format!("{name}: {e}\n  {}", String::from_utf8_lossy(&m)));
            }
        }
    }
    none_failed(&failures, &count.to_string());
}

#[test]
fn every_mutation_of_a_latch_answer_can_only_stop() {
    let s = fleet_scenario(false);
    let base = synced_robot(&s, 1, &reference_at(1.0, 0));
    let stop = FleetCommand::new(Order::Stop, 4, "operator", "why");
    let resume = FleetCommand::new(Order::Resume, 5, "operator", "");
    let corpus = [
        Latched {
            stopped: true,
            command: Some(stop.clone()),
            hazards: HazardSet::EMPTY,
            refused: None,
        },
        Latched {
            stopped: false,
            command: Some(resume),
            hazards: HazardSet::EMPTY,
            refused: None,
        },
        Latched {
            stopped: false,
            command: None,
            hazards: HazardSet::EMPTY,
            refused: None,
        },
        Latched {
            stopped: true,
            command: Some(stop),
            hazards: HazardSet::EMPTY,
            refused: Some(echelon_fleet::command::Refusal {
                seq: 6,
                stamp_unix_ns: 1,
                by: "operator".into(),
                why: echelon_fleet::command::NO_VALID_PROOF.into(),
            }),
        },
    ];
    let mut failures = Vec::new();
    for valid in &corpus {
        assert_eq!(Latched::decode(&valid.encode()).as_ref(), Some(valid));
        for (name, m) in json_mutations(&valid.encode()) {
            let check = || {
                let mut r = base.clone();
                let counts = r.command_counts();
                r.on_latch_answer(&m);
                let decoded = Latched::decode(&m);
                // What a latch answer carries is a command by the command
                // key's rules (a sender named, a reason of bounded length).
                if let Some(c) = decoded.as_ref().and_then(|l| l.command.as_ref())
                    && let Err(e) = FleetCommand::decode(&c.encode())
                {
                    return Err(format!(
                        "a latch answer accepted a command refused: {e}: {c:?}"
                    ));
                }
                let stopping = decoded.as_ref().is_some_and(|l| l.stopped);
                if r.is_stopped() != stopping {
                    return Err(format!("{decoded:?} left it stopped = {}", r.is_stopped()));
                }
                if !stopping && r.command_counts() != counts {
                    return Err("a latch answer that does not stop changed the counts".into());
                }
                run_ticks(&mut r, 0.02, 3).map(|_| ())
            };
            if let Err(e) = no_panic(&m, check) {
                failures.push(format!("{name}: {e}\n  {}", String::from_utf8_lossy(&m)));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

// ---------------------------------------------------------------------------
// The collector.

/// Counts what the collector logs.
#[derive(Debug, Default)]
struct Counting {
    logged: Vec<(String, Stamp)>,
    rows: Vec<AgentSample>,
    poses: usize,
}

impl RecordSink for Counting {
    fn log(
        &mut self,
        channel: Channel<'_>,
        stamp: Stamp,
        _data: &[u8],
    ) -> Result<(), echelon_fleet::FleetError> {
        self.logged.push((channel.topic().to_owned(), stamp));
        Ok(())
    }
    fn row(&mut self, sample: &AgentSample) -> Result<(), echelon_fleet::FleetError> {
        self.rows.push(*sample);
        Ok(())
    }
    fn pose(
        &mut self,
        _k: u32,
        _pose: &ScenePose,
        _stamp: Stamp,
    ) -> Result<(), echelon_fleet::FleetError> {
        self.poses += 1;
        Ok(())
    }
}

fn rejected(c: &Collector) -> u64 {
    c.report().rejected.values().sum()
}

#[test]
fn every_single_mutation_is_logged_once_by_the_collector() {
    let keys = Keys::new("fuzz");
    // A robot's own stats, as it publishes them.
    let mut r = synced_robot(&fleet_scenario(false), 1, &reference_at(1.0, 0));
    let stats = serde_json::to_vec(&r.finish()).expect("stats JSON");
    let command = FleetCommand::new(Order::Stop, 3, "operator", "test").encode();
    let json = |b: &[u8], _: usize| json_mutations(b);
    let mut count = 0;
    for (key, corpus, mutations) in [
        (
            keys.reference(),
            wire_corpus(),
            single_mutations as fn(&[u8], usize) -> Vec<Mutant>,
        ),
        (keys.state(1), wire_corpus(), single_mutations),
        (keys.stats(1), vec![stats], json),
        (keys.command(), vec![command], json),
    ] {
        count += every_mutation(&format!("collector {key}"), &corpus, 0, mutations, |b| {
            let mut c = Collector::new(keys.clone());
            let mut sink = Counting::default();
            c.on_message(&key, b, 1_000, &mut sink)
                .map_err(|e| e.to_string())?;
            if sink.logged.len() != 1 || c.report().received != 1 || c.report().logged != 1 {
                return Err(format!("logged {:?}", sink.logged));
            }
            let refused = rejected(&c);
            let on_rejected = sink.logged[0].0 == "/rejected";
            if on_rejected != (refused == 1) {
                return Err(format!("on {} with {refused} rejected", sink.logged[0].0));
            }
            if !on_rejected && matches!(keys.classify(&key), KeyKind::Reference | KeyKind::State(_))
            {
                check_wire(b)?;
            }
            for row in &sink.rows {
                finite(
                    "a trajectory row",
                    &[row.t, row.x, row.y, row.theta, row.v, row.omega],
                )?;
            }
            Ok(())
        });
    }
    eprintln!("{count} collector mutations checked");
}

// ---------------------------------------------------------------------------
// ROS 2: CDR messages and their consumers.

/// The rclpy fixtures: type name → bytes.
fn rclpy_fixtures() -> BTreeMap<String, Vec<u8>> {
    include_str!("fixtures/rclpy_messages.txt")
        .lines()
        .filter_map(|l| l.split_once(' '))
        .map(|(ty, h)| (ty.to_owned(), unhex(h.trim())))
        .collect()
}

fn rclpy(ty: &MessageType) -> Vec<u8> {
    rclpy_fixtures()
        .remove(ty.name)
        .unwrap_or_else(|| panic!("no rclpy fixture of {}", ty.name))
}

/// The values `fixtures/rclpy_messages.py` serialised, field by field.
fn rclpy_twist() -> Twist {
    Twist {
        linear: msgs::Vector3 {
            x: 0.5,
            y: -0.125,
            z: 0.0625,
        },
        angular: msgs::Vector3 {
            x: 0.03125,
            y: -0.75,
            z: 1.5,
        },
    }
}

fn quat() -> msgs::Quaternion {
    msgs::Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.6,
        w: 0.8,
    }
}

fn header(sec: i32, nanosec: u32, frame: &str) -> msgs::Header {
    msgs::Header {
        stamp: Time { sec, nanosec },
        frame_id: frame.to_owned(),
    }
}

fn rclpy_odometry() -> Odometry {
    Odometry {
        header: header(12, 500_000_000, "odom"),
        child_frame_id: "base_link".to_owned(),
        pose: msgs::PoseWithCovariance {
            pose: msgs::Pose {
                position: msgs::Point {
                    x: 1.25,
                    y: -2.5,
                    z: 0.0,
                },
                orientation: quat(),
            },
            covariance: std::array::from_fn(|i| i as f64 * 0.01),
        },
        twist: msgs::TwistWithCovariance {
            twist: Twist::planar(0.4, -0.2),
            covariance: std::array::from_fn(|i| i as f64 * -0.5),
        },
    }
}

fn rclpy_pose_stamped() -> PoseStamped {
    PoseStamped {
        header: header(3, 7, "mocap"),
        pose: msgs::Pose {
            position: msgs::Point {
                x: 0.5,
                y: 1.5,
                z: 0.0,
            },
            orientation: quat(),
        },
    }
}

fn rclpy_pose_with_covariance() -> PoseWithCovarianceStamped {
    let mut covariance = [0.0; 36];
    for (i, v) in [0, 1, 5, 6, 7, 11, 30, 31, 35]
        .into_iter()
        .zip([0.25, 0.01, -0.02, 0.01, 0.5, 0.03, -0.02, 0.03, 0.07])
    {
        covariance[i] = v;
    }
    PoseWithCovarianceStamped {
        header: header(40, 250_000_000, "map"),
        pose: msgs::PoseWithCovariance {
            pose: msgs::Pose {
                position: msgs::Point {
                    x: -3.0,
                    y: 4.0,
                    z: 0.0,
                },
                orientation: quat(),
            },
            covariance,
        },
    }
}

/// ROS 2's bytes decode to the values it serialised; ours decode to the
/// same and differ from ROS 2's only in padding (which Fast-CDR leaves
/// uninitialised); both round-trip.
fn check_rclpy<M: RosMessage + PartialEq + std::fmt::Debug>(expected: &M) {
    let theirs = rclpy(&M::TYPE);
    let decoded = M::from_cdr_finite(&theirs).unwrap_or_else(|e| panic!("{}: {e}", M::TYPE.name));
    assert_eq!(&decoded, expected, "{}", M::TYPE.name);
    let ours = expected.to_cdr();
    assert_eq!(ours.len(), theirs.len(), "{}", M::TYPE.name);
    assert_eq!(M::from_cdr_finite(&ours).as_ref(), Ok(expected));
    // Where they differ, ours holds zero padding.
    for (i, (a, b)) in ours.iter().zip(&theirs).enumerate() {
        if a != b {
            assert_eq!(
                *a,
                0,
                "{} byte {i}: ours {a:02x}, ROS 2's {b:02x}",
                M::TYPE.name
            );
        }
    }
}

#[test]
fn ros2s_own_bytes_decode_to_what_it_serialised_and_round_trip() {
    check_rclpy(&rclpy_twist());
    check_rclpy(&TwistStamped {
        header: header(1_733_227_200, 123_456_789, "base_link"),
        twist: rclpy_twist(),
    });
    check_rclpy(&rclpy_odometry());
    check_rclpy(&rclpy_pose_stamped());
    check_rclpy(&rclpy_pose_with_covariance());
}

/// `from_cdr` never panics; what `from_cdr_finite` accepts is finite and
/// re-encodes to itself.
fn check_cdr<M: RosMessage + PartialEq + std::fmt::Debug>(b: &[u8]) -> Result<(), String> {
    let _ = M::from_cdr(b);
    match M::from_cdr_finite(b) {
        Err(_) => Ok(()),
        Ok(m) => {
            if let Some(f) = m.first_non_finite() {
                return Err(format!("accepted a non-finite {f}"));
            }
            match M::from_cdr_finite(&m.to_cdr()) {
                Ok(back) if back == m => Ok(()),
                other => Err(format!("{m:?} re-encoded decodes to {other:?}")),
            }
        }
    }
}

#[test]
fn every_single_mutation_of_every_ros2_message_is_refused_or_finite() {
    let stamp = Time::from_nanos(1_733_227_200_123_456_789);
    let mut count = 0;
    count += every_single_mutation(
        "Twist",
        &[rclpy(&msgs::TWIST), Twist::planar(0.3, -0.4).to_cdr()],
        4,
        check_cdr::<Twist>,
    );
    count += every_single_mutation(
        "TwistStamped",
        &[
            rclpy(&msgs::TWIST_STAMPED),
            TwistStamped::planar(0.3, -0.4, stamp, "base_link").to_cdr(),
            TwistStamped::planar(0.3, -0.4, Time::default(), "").to_cdr(),
        ],
        4,
        check_cdr::<TwistStamped>,
    );
    count += every_single_mutation(
        "Odometry",
        &[
            rclpy(&msgs::ODOMETRY),
            Odometry::planar(1.0, 2.0, 0.5, 0.2, -0.1, stamp, "odom", "base_link").to_cdr(),
        ],
        4,
        check_cdr::<Odometry>,
    );
    count += every_single_mutation(
        "PoseStamped",
        &[
            rclpy(&msgs::POSE_STAMPED),
            PoseStamped::planar(1.0, 2.0, 0.5, stamp, "mocap").to_cdr(),
        ],
        4,
        check_cdr::<PoseStamped>,
    );
    count += every_single_mutation(
        "PoseWithCovarianceStamped",
        &[
            rclpy(&msgs::POSE_WITH_COVARIANCE_STAMPED),
            rclpy_pose_with_covariance().to_cdr(),
        ],
        4,
        check_cdr::<PoseWithCovarianceStamped>,
    );
    eprintln!("{count} CDR mutations checked");
    assert_eq!(&rclpy(&msgs::TWIST)[..2], &ENCAPSULATION_CDR_LE[..2]);
}

#[test]
fn every_single_mutation_of_an_attachment_is_refused_or_exact() {
    let valid = Attachment {
        sequence_number: 42,
        source_timestamp_ns: 1_733_227_200_000_000_000,
        gid: std::array::from_fn(|i| i as u8 * 17),
    }
    .encode();
    assert_eq!(Attachment::decode(&valid).map(|a| a.encode()), Ok(valid));
    every_single_mutation("attachment", &[valid.to_vec()], 0, |b| {
        let ok = b.len() == ATTACHMENT_LEN && usize::from(b[16]) == GID_LEN;
        match Attachment::decode(b) {
            Ok(a) if ok && a.encode()[..] == *b => Ok(()),
            Err(_) if !ok => Ok(()),
            other => Err(format!("decoded to {other:?}")),
        }
    });
}

/// Fleet and rmw_zenoh keys, mutated as strings: no parser panics, and
/// what a check accepts names the type and hash it expects.
#[test]
fn mutated_keys_never_panic_and_only_the_right_type_passes() {
    let keys = Keys::new("fuzz");
    let fleet_keys = [
        keys.reference(),
        keys.state(3),
        keys.stats(2),
        keys.command(),
        keys.latch("robot1"),
    ];
    let ros_keys: Vec<(KeyScheme, String, MessageType)> = [
        KeyScheme::RmwZenoh,
        KeyScheme::RmwZenohHumble,
        KeyScheme::Bridge,
    ]
    .into_iter()
    .flat_map(|scheme| {
        [msgs::ODOMETRY, msgs::TWIST_STAMPED, msgs::POSE_STAMPED]
            .map(|ty| (scheme, topic_key(scheme, 0, "/robot1/odom", &ty), ty))
    })
    .collect();
    let mutate = |k: &str| -> Vec<String> {
        let chars: Vec<char> = k.chars().collect();
        let mut out = Vec::new();
        for i in 0..=chars.len() {
            out.push(chars[..i].iter().collect());
            for c in ['/', '*', '\0', 'é', ' ', '\n', '_', '1', ':'] {
                let mut m = chars.clone();
                if i < m.len() {
                    m[i] = c;
                    out.push(m.iter().collect());
                }
                let mut m = chars.clone();
                m.insert(i, c);
                out.push(m.iter().collect());
            }
        }
        out.push(format!("{k}/{k}"));
        out.push(k.replace('/', "//"));
        out
    };
    let mut failures = Vec::new();
    for k in &fleet_keys {
        for m in mutate(k) {
            if let Err(e) = no_panic(m.as_bytes(), || {
                let kind = keys.classify(&m);
                let _ = keys.latch_holder(&m);
                if let KeyKind::State(a) | KeyKind::Stats(a) = kind
                    && a == 0
                {
                    return Err(format!("{m:?} classified {kind:?}"));
                }
                Ok(())
            }) {
                failures.push(e);
            }
        }
    }
    for (scheme, k, ty) in &ros_keys {
        assert_eq!(check_topic_key(*scheme, k, ty), Ok(()), "{k}");
        for m in mutate(k) {
            if let Err(e) = no_panic(m.as_bytes(), || {
                let _ = fully_qualified_topic("/ns", &m);
                let ok = check_topic_key(*scheme, &m, ty).is_ok();
                if ok && *scheme != KeyScheme::Bridge && !m.contains(&ty.dds_name()) {
                    return Err(format!("{m:?} accepted as {}", ty.name));
                }
                Ok(())
            }) {
                failures.push(e);
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Records the commands sent, a clock advancing 1 ms per read.
#[derive(Debug, Default)]
struct Sent {
    commands: Vec<Vec<u8>>,
    now: std::cell::Cell<i64>,
}

impl CmdSink for Sent {
    fn now_ns(&self) -> i64 {
        self.now.set(self.now.get() + 1_000_000);
        self.now.get()
    }
    fn send(&mut self, payload: &[u8], _attachment: &[u8]) -> Result<(), String> {
        self.commands.push(payload.to_vec());
        Ok(())
    }
}

fn ros2_link() -> Ros2Link {
    let src = "[sim]\nduration = 1.0\ndt = 0.01\n[reference.circle]\nspeed = 0.1\nturn_rate = 0.1\nstart = { x = 0.0, y = 0.0, theta = 0.0 }\n[fleet.ros2]\nodom_rate = 10.0\ncmd_vel_timeout = 0.5\n[[agents]]\nstart = { x = 0.0, y = 0.0, theta = 0.0 }\nleader = \"reference\"\n";
    let s = Scenario::parse(src, "fuzz.toml", None).unwrap_or_else(|e| panic!("{e}"));
    s.fleet().unwrap_or_else(|e| panic!("{e}")).ros2[0].clone()
}

fn key_of(link: &Ros2Link, topic: &str, ty: &MessageType) -> String {
    let fq = fully_qualified_topic(&link.namespace, topic).expect("a valid topic");
    topic_key(link.key_scheme, link.domain_id, &fq, ty)
}

fn limited_base() -> VelocityBase {
    VelocityBase::new(VelocityBaseSpec {
        v_max: 0.5,
        omega_max: 2.0,
        ..VelocityBase::IDEAL.spec()
    })
    .expect("a base with speed limits")
}

fn odometry_corpus() -> Vec<Vec<u8>> {
    vec![
        rclpy(&msgs::ODOMETRY),
        Odometry::planar(
            0.3,
            -0.2,
            2.5,
            0.2,
            -0.1,
            Time::from_nanos(2_000_000_000),
            "odom",
            "base_link",
        )
        .to_cdr(),
    ]
}

fn state_values(s: &State) -> [f64; 5] {
    [s.x, s.y, s.theta, s.v, s.omega]
}

/// The ROS 2 drive's odometry: one counter per sample; an accepted one
/// is the robot's state, finite; a refused one changes nothing.
#[test]
fn every_single_mutation_of_odometry_is_counted_and_refused_or_finite() {
    let link = ros2_link();
    let key = key_of(&link, &link.odom, &msgs::ODOMETRY);
    let first = Odometry::planar(
        0.0,
        0.0,
        0.1,
        0.0,
        0.0,
        Time::from_nanos(1_000_000_000),
        "odom",
        "base_link",
    )
    .to_cdr();
    let drive = || {
        let mut d = Ros2Drive::new(link.clone(), limited_base(), [7; 16], Sent::default());
        d.on_odom(&key, &first, 0.0).expect("a valid odometry");
        d.advance(0.01);
        d
    };
    let check = |b: &[u8]| {
        let mut d = drive();
        let before = *d.counters();
        let state = d.state();
        let result = d.on_odom(&key, b, 0.01);
        let outcomes = |c: &Ros2Counters| {
            [
                c.odom_received,
                c.odom_accepted,
                c.odom_wrong_type,
                c.odom_malformed,
                c.odom_non_finite,
                c.odom_wrong_frames,
            ]
        };
        counted_once(outcomes(&before), outcomes(d.counters()), &result)?;
        if result.is_err() && d.state() != state {
            return Err(format!("refused ({result:?}) but the state changed"));
        }
        // No orientation that is not a rotation (a zero quaternion was yaw
        // 0) becomes the robot's heading.
        if result.is_ok() {
            let odom = Odometry::from_cdr_finite(b).map_err(|e| e.to_string())?;
            if !tf2_takes(&odom.pose.pose.orientation) {
                return Err(format!(
                    "accepted the orientation {:?}",
                    odom.pose.pose.orientation
                ));
            }
        }
        d.advance(0.02);
        let s = d.state().ok_or("no state after an odometry sample")?;
        finite("the drive's state", &state_values(&s))?;
        if let Some(o) = d.odometry() {
            finite(
                "the drive's raw odometry",
                &[o.raw[0], o.raw[1], o.raw[2], o.age],
            )?;
        }
        let (dv, domega) = d.accelerations();
        finite(
            "the drive's accelerations",
            &[dv, domega, d.position_sigma()],
        )
    };
    let mut n = every_single_mutation("odometry", &odometry_corpus(), 4, check);
    n += every_mutation("odometry", &odometry_corpus(), 4, pair_mutations, check);
    n += every_mutation(
        "odometry",
        &odometry_corpus(),
        4,
        quaternion_mutations,
        check,
    );
    eprintln!("{n} odometry mutations checked");
}

/// One message, counted once: from counters `before` to `after` (received
/// first, then the outcomes, accepted first), received moved by one and
/// exactly one outcome by one, the one the handler's answer `result` names.
fn counted_once<const N: usize, T: std::fmt::Debug, E: std::fmt::Debug>(
    before: [u64; N],
    after: [u64; N],
    result: &Result<T, E>,
) -> Result<(), String> {
    let moved: Vec<u64> = after.iter().zip(before).map(|(a, b)| a - b).collect();
    if moved[0] != 1 || moved[1..].iter().sum::<u64>() != 1 {
        return Err(format!("counted {moved:?} (received first)"));
    }
    if result.is_ok() != (moved[1] == 1) {
        return Err(format!("{result:?} counted {moved:?} (received first)"));
    }
    Ok(())
}

/// The paper's experiment on lagged velocity bases under the kinematic law
/// (`scenarios/experiment-circle-velocity.toml`), its robots on ROS 2.
fn ros2_robots() -> String {
    include_str!("../../../scenarios/experiment-circle-velocity.toml").to_owned()
        + "\n[fleet.ros2]\n"
}

/// Agent 1 of [`ros2_robots`] on a ROS 2 drive, synced on the reference
/// and its first odometry, fed `b` as its next odometry and ticked: the
/// law's commands on `cmd_vel` are finite (none replaced by zero for not
/// being finite) and within the base's limits. Counts in `diverged` a
/// robot the odometry sent past its divergence guard.
fn check_ros2_robot(b: &[u8], diverged: &mut usize) -> Result<(), String> {
    static RIG: std::sync::OnceLock<(RobotConfig, Ros2Link)> = std::sync::OnceLock::new();
    let (config, link) = RIG.get_or_init(|| {
        let s =
            Scenario::parse(&ros2_robots(), "fuzz.toml", None).unwrap_or_else(|e| panic!("{e}"));
        let link = s.fleet().unwrap_or_else(|e| panic!("{e}")).ros2[0].clone();
        (robot_config(&s, 1), link)
    });
    let base = config
        .spec
        .velocity_robot()
        .expect("a velocity robot")
        .base();
    let key = key_of(link, &link.odom, &msgs::ODOMETRY);
    let first = Odometry::planar(
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        Time::from_nanos(1),
        "odom",
        "base_link",
    )
    .to_cdr();
    let cmd_ty = *echelon_fleet::ros2::drive::cmd_vel_type(link);
    let drive = Ros2Drive::new(link.clone(), base, [9; 16], Sent::default());
    let mut r = Robot::new(config.clone(), drive, 5);
    r.on_message(&reference_at(1.0, 0), 0.0);
    let t = r.fleet_time(0.0);
    r.plant_mut()
        .on_odom(&key, &first, t)
        .map_err(|e| e.to_string())?;
    r.tick(0.0);
    let t = r.fleet_time(0.02);
    if r.plant_mut().on_odom(&key, b, t).is_ok() {
        let odom = Odometry::from_cdr_finite(b).map_err(|e| e.to_string())?;
        if !tf2_takes(&odom.pose.pose.orientation) {
            return Err(format!(
                "the drive took the orientation {:?}",
                odom.pose.pose.orientation
            ));
        }
    }
    let period = r.config().period;
    for k in 0..3 {
        let now = 0.02 + f64::from(k) * period;
        if r.is_due(now) {
            r.tick(now);
        }
    }
    *diverged += usize::from(r.diverged().is_some());
    let d = r.plant();
    if d.counters().cmd_non_finite != 0 {
        return Err(format!(
            "the law asked for non-finite commands: {:?}",
            d.counters()
        ));
    }
    for payload in &d.sink().commands {
        let (v, omega) = if cmd_ty == msgs::TWIST_STAMPED {
            let c = TwistStamped::from_cdr_finite(payload).map_err(|e| e.to_string())?;
            (c.twist.linear.x, c.twist.angular.z)
        } else {
            let c = Twist::from_cdr_finite(payload).map_err(|e| e.to_string())?;
            (c.linear.x, c.angular.z)
        };
        if v.abs() > 0.3 || omega.abs() > 2.0 {
            return Err(format!("sent ({v}, {omega}) beyond the limits"));
        }
    }
    Ok(())
}

/// A ROS 2 robot fed mutated odometry: whatever its drive accepts, the
/// law's commands on `cmd_vel` are finite and within the base's limits.
#[test]
fn a_ros2_robot_fed_mutated_odometry_commands_finite_values() {
    let diverged = std::cell::Cell::new(0);
    let check = |b: &[u8]| {
        let mut n = diverged.get();
        let r = check_ros2_robot(b, &mut n);
        diverged.set(n);
        r
    };
    let corpus = odometry_corpus();
    let mut n = every_single_mutation("a ROS 2 robot's odometry", &corpus, 4, check);
    n += every_mutation(
        "a ROS 2 robot's odometry",
        &corpus[..1],
        4,
        pair_mutations,
        check,
    );
    n += every_mutation(
        "a ROS 2 robot's odometry",
        &corpus,
        4,
        quaternion_mutations,
        check,
    );
    eprintln!(
        "{n} odometry mutations through a ROS 2 robot checked; {} stopped it as diverged",
        diverged.get()
    );
}

/// The divergence guard's position bound of [`fix_input`]'s robot, m (its
/// `[sim] bounds`): no fix may put it farther from the world origin.
const FIX_BOUND: f64 = 50.0;

/// The last raw odometry [`fix_input`] fed: the pose of the robot in its
/// odom frame now.
const FIX_RAW_NOW: Pose = Pose {
    x: 0.008,
    y: 0.0,
    theta: 0.0,
};

fn fix_input(message: FixMessage) -> FixInput {
    let source = FixSource {
        topic: "/mocap/robot1/pose".to_owned(),
        message,
        frame: "map".to_owned(),
        frame_origin: Pose::default(),
        timeout: None,
        tolerance: None,
        gate: true,
    };
    let spec = FixSpec::new(FixSchedule::Period(0.1), Fusion::Ekf)
        .and_then(|f| f.with_noise(0.01, Some(0.02)))
        .expect("a fix spec");
    let model = OdometryModel {
        errors: ErrorModel::PERFECT,
        wheels: (0.1, 0.03),
        sample_period: 0.02,
        top_speed: 0.5,
    };
    let mut f = FixInput::new(
        1,
        source,
        KeyScheme::RmwZenoh,
        &spec,
        model,
        Pose::default(),
        1.0,
    )
    .unwrap_or_else(|e| panic!("{e}"))
    .with_bounds(echelon::guard::Bounds::new(100.0, 100.0, FIX_BOUND).expect("bounds"));
    for k in 0..5 {
        let t = f64::from(k) * 0.02;
        f.on_odom(
            1_000_000_000 + i64::from(k) * 20_000_000,
            Pose {
                x: 0.1 * t,
                y: 0.0,
                theta: 0.0,
            },
            t,
        );
    }
    f
}

/// The orientation of a fix message `b` of type `message` (`None`: it does
/// not decode finite).
fn fix_orientation(message: FixMessage, b: &[u8]) -> Option<msgs::Quaternion> {
    match message {
        FixMessage::PoseStamped => PoseStamped::from_cdr_finite(b)
            .ok()
            .map(|m| m.pose.orientation),
        FixMessage::PoseWithCovarianceStamped => PoseWithCovarianceStamped::from_cdr_finite(b)
            .ok()
            .map(|m| m.pose.pose.orientation),
    }
}

fn pose_values(p: &Pose) -> [f64; 3] {
    [p.x, p.y, p.theta]
}

/// The fixes: one counter per sample; an accepted fix leaves a finite
/// correction and covariance, a refused one changes neither.
#[test]
fn every_single_mutation_of_a_fix_is_counted_and_refused_or_finite() {
    let stamp = Time::from_nanos(1_060_000_000);
    let mut count = 0;
    for (message, corpus) in [
        (
            FixMessage::PoseStamped,
            vec![
                PoseStamped::planar(0.006, 0.001, 0.01, stamp, "map").to_cdr(),
                PoseStamped {
                    header: header(1, 60_000_000, "map"),
                    ..rclpy_pose_stamped()
                }
                .to_cdr(),
            ],
        ),
        (
            FixMessage::PoseWithCovarianceStamped,
            vec![
                PoseWithCovarianceStamped::planar(
                    0.006,
                    0.001,
                    0.01,
                    [[1e-4, 0.0, 0.0], [0.0, 1e-4, 0.0], [0.0, 0.0, 4e-4]],
                    stamp,
                    "map",
                )
                .to_cdr(),
            ],
        ),
    ] {
        let key = topic_key(
            KeyScheme::RmwZenoh,
            0,
            "/mocap/robot1/pose",
            fix_type(message),
        );
        // Before any fix (the first is taken as it is) and after one (gated).
        let fresh = fix_input(message);
        let mut fixed = fix_input(message);
        fixed.on_fix(&key, &corpus[0], 0.08).expect("a valid fix");
        for base in [&fresh, &fixed] {
            let check = |b: &[u8]| {
                let mut f = base.clone();
                let before = *f.counters();
                let correction = f.correction();
                let result = f.on_fix(&key, b, 0.09);
                let after = *f.counters();
                if after.received != before.received + 1 {
                    return Err("not counted as received".into());
                }
                let refusals = |c: &echelon_fleet::ros2::fixes::FixCounters| {
                    c.wrong_type
                        + c.non_finite
                        + c.wrong_frame
                        + c.malformed
                        + c.unmatched
                        + c.gated
                        + c.beyond_bounds
                };
                match &result {
                    Err(e) => {
                        if refusals(&after) != refusals(&before) + 1
                            || after.applied != before.applied
                        {
                            return Err(format!("refused ({e}) but counted {after:?}"));
                        }
                        if f.correction() != correction {
                            return Err(format!("refused ({e}) but the correction moved"));
                        }
                    }
                    Ok(()) => {
                        if after.applied != before.applied + 1 {
                            return Err(format!("accepted but counted {after:?}"));
                        }
                        // First fix or not, it leaves the robot within its
                        // guard's bound, with a heading from a rotation.
                        let now = f.correction().compose(&FIX_RAW_NOW);
                        if now.x.hypot(now.y) > FIX_BOUND {
                            return Err(format!("accepted a fix that put the robot at {now:?}"));
                        }
                        match fix_orientation(message, b) {
                            Some(q) if tf2_takes(&q) => {}
                            q => return Err(format!("accepted the orientation {q:?}")),
                        }
                    }
                }
                finite("the correction", &pose_values(&f.correction()))?;
                if let Some(p) = f.covariance() {
                    finite("the covariance", &p.concat())?;
                }
                Ok(())
            };
            count += every_single_mutation("fix", &corpus, 4, check);
            count += every_mutation("fix", &corpus[..1], 4, pair_mutations, check);
            count += every_mutation("fix", &corpus, 4, quaternion_mutations, check);
        }
    }
    eprintln!("{count} fix mutations checked");
}

/// The simulated base's `cmd_vel` and attachment: one counter per sample;
/// what it follows is finite and within its limits.
#[test]
fn every_single_mutation_of_a_cmd_vel_is_counted_and_refused_or_followed_within_limits() {
    let link = ros2_link();
    let ty = *echelon_fleet::ros2::drive::cmd_vel_type(&link);
    let key = key_of(&link, &link.cmd_vel, &ty);
    let robot = VelocityRobot::new(limited_base(), 0.08, 0.033).expect("a robot");
    let base = || {
        let drive = SimulatedDrive::new(
            Drive::Velocity(robot),
            State::at_rest(0.0, 0.0, 0.0),
            0.0,
            1e-3,
        );
        SimBase::new(link.clone(), drive, [3; 16])
    };
    let wall = 1_733_227_200_000_000_000;
    let attachment = Attachment {
        sequence_number: 1,
        source_timestamp_ns: wall,
        gid: [1; 16],
    }
    .encode();
    let mut corpus = Vec::new();
    for (v, omega) in [(0.2, 0.5), (-0.4, -1.5), (3.0, 9.0)] {
        let mut buf = Vec::new();
        encode_cmd_vel(&link, VelocityCommand { v, omega }, wall, &mut buf);
        corpus.push(buf);
    }
    if ty == msgs::TWIST_STAMPED {
        corpus.push(rclpy(&msgs::TWIST_STAMPED));
    }
    let check = |payload: &[u8], attachment: &[u8]| -> Result<(), String> {
        let mut b = base();
        let before = *b.counters();
        let result = b.on_cmd(&key, payload, Some(attachment), 0.1, wall);
        let outcomes = |c: &BaseCounters| {
            [
                c.cmd_received,
                c.cmd_accepted,
                c.cmd_wrong_type,
                c.cmd_malformed,
                c.cmd_non_finite,
                c.cmd_no_attachment,
                c.cmd_stale,
            ]
        };
        counted_once(outcomes(&before), outcomes(b.counters()), &result)?;
        let f = b.followed();
        finite("the followed command", &[f.v, f.omega])?;
        if f.v.abs() > 0.5 || f.omega.abs() > 2.0 {
            return Err(format!("followed {f:?} beyond the limits"));
        }
        let _ = b.tick(0.5, wall + 400_000_000);
        finite("the base's odometry", &state_values(&b.odometry()))
    };
    let mut n = every_single_mutation("cmd_vel", &corpus, 4, |p| check(p, &attachment));
    n += every_single_mutation("a cmd_vel's attachment", &[attachment.to_vec()], 0, |a| {
        check(&corpus[0], a)
    });
    eprintln!("{n} cmd_vel mutations checked");
}

/// The collector's ROS 2 recording: one record per sample, refused ones
/// on `/rejected`.
#[test]
fn every_single_mutation_of_a_recorded_ros2_sample_is_logged_once() {
    let link = ros2_link();
    let topics = RosTopic::of_link(&link)
        .expect("the link's topics")
        .to_vec();
    let key = key_of(&link, &link.odom, &msgs::ODOMETRY);
    every_single_mutation("a recorded odometry", &odometry_corpus(), 4, |b| {
        let mut c = Collector::with_ros2(Keys::new("fuzz"), topics.clone()).expect("topics");
        let mut sink = Counting::default();
        c.on_ros_sample(&key, b, Some(&[0u8; 3]), 1_000, &mut sink)
            .map_err(|e| e.to_string())?;
        let r = c.report();
        if sink.logged.len() != 1 || r.ros_recorded + r.ros_refused != 1 {
            return Err(format!("logged {:?}", sink.logged));
        }
        let refused = Odometry::from_cdr(b).is_err();
        if refused != (r.ros_refused == 1) {
            return Err(format!(
                "recorded {} refused {}",
                r.ros_recorded, r.ros_refused
            ));
        }
        Ok(())
    });
}

/// A reference 1.8e308 m away is a finite, valid message, but the law
/// overflowed on it and the robot stopped as diverged, on one message. A
/// sample beyond the divergence guard's default bounds (position, speeds,
/// turn rate, acceleration, or a time past `MAX_SAMPLE_TIME`) is refused and
/// counted as malformed, and the robot goes on as if it had not come; one
/// just within them is followed.
#[test]
fn a_reference_beyond_the_guards_bounds_is_refused_and_counted() {
    let s = fleet_scenario(false);
    let base = synced_robot(&s, 1, &reference_at(1.0, 0));
    let expected = run_ticks(&mut base.clone(), 0.02, 3).unwrap_or_else(|e| panic!("{e}"));
    // The scenario's bounds are the defaults: the larger of the two.
    let bounds = base.config().bounds;
    assert_eq!(bounds, echelon::guard::Bounds::DEFAULT);
    // (byte offset of the f64, value just beyond its bound)
    let beyond = [
        (16, 1.01 * echelon_fleet::link::MAX_SAMPLE_TIME),
        (24, 1.01 * bounds.distance),
        (24, f64::MAX),
        (40, 1.01 * bounds.speed),
        (56, 1.01 * bounds.speed * bounds.turn_rate),
        (72, -1.01 * bounds.speed),
        (80, 1.01 * bounds.turn_rate),
    ];
    for (at, value) in beyond {
        let mut far = reference_at(1.02, 1);
        far[at..at + 8].copy_from_slice(&value.to_le_bytes());
        assert!(matches!(wire::decode(&far), Ok(Message::Reference(..))));
        let mut r = base.clone();
        let before = r.counters().malformed;
        r.on_message(&far, 0.02);
        assert_eq!(r.counters().malformed, before + 1, "byte {at} = {value:e}");
        let commands = run_ticks(&mut r, 0.02, 3).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(commands, expected, "byte {at} = {value:e}");
        assert!(r.diverged().is_none(), "byte {at} = {value:e}");
    }
    // Within: followed (a reference 0.99 of the distance bound away).
    let mut near = reference_at(1.02, 1);
    near[24..32].copy_from_slice(&(0.99 * bounds.distance).to_le_bytes());
    let mut r = base.clone();
    r.on_message(&near, 0.02);
    assert_eq!(r.counters().malformed, 0);
}

// ---------------------------------------------------------------------------
// Random combinations, fixed seeds.

proptest! {
    #![proptest_config(fixed(300, 0xec_0004))]

    /// One to four mutations of an odometry sample through a ROS 2 robot.
    #[test]
    fn a_ros2_robot_counts_or_follows_randomly_mutated_odometry(
        which in 0..2usize,
        ops in prop::collection::vec(op(), 1..=4),
    ) {
        let b = apply(&odometry_corpus()[which], &ops, 4);
        let r = no_panic(&b, || check_ros2_robot(&b, &mut 0));
        prop_assert!(r.is_ok(), "{ops:?} ({}): {r:?}", hex(&b));
    }
}

proptest! {
    #![proptest_config(fixed(3000, 0xec_0001))]

    /// One to four mutations of a wire message: refused, or finite and
    /// round-tripping; a robot following it counts a refusal and commands
    /// finite values.
    #[test]
    fn mutated_wire_messages_are_refused_or_finite(
        which in any::<prop::sample::Index>(),
        ops in prop::collection::vec(op(), 1..=4),
    ) {
        let corpus = wire_corpus();
        let b = apply(&corpus[which.index(corpus.len())], &ops, 0);
        let r = no_panic(&b, || check_wire(&b));
        prop_assert!(r.is_ok(), "{ops:?}: {r:?}");
    }
}

proptest! {
    #![proptest_config(fixed(400, 0xec_0002))]

    #[test]
    fn a_robot_counts_or_follows_randomly_mutated_references(
        ops in prop::collection::vec(op(), 1..=4),
    ) {
        let s = fleet_scenario(false);
        let base = synced_robot(&s, 1, &reference_at(1.0, 0));
        let expected = run_ticks(&mut base.clone(), 0.02, 3).expect("the unmutated robot");
        let b = apply(&reference_at(1.02, 1), &ops, 0);
        let r = no_panic(&b, || check_leader_stream(&base, &expected, &b));
        prop_assert!(r.is_ok(), "{ops:?}: {r:?}");
    }
}

proptest! {
    #![proptest_config(fixed(3000, 0xec_0003))]

    /// One to four mutations of a ROS 2 message: refused, or finite and
    /// round-tripping.
    #[test]
    fn mutated_ros2_messages_are_refused_or_finite(
        which in 0..5usize,
        ops in prop::collection::vec(op(), 1..=4),
    ) {
        let stamp = Time::from_nanos(5);
        let (b, r) = match which {
            0 => {
                let b = apply(&rclpy(&msgs::TWIST), &ops, 4);
                let r = no_panic(&b, || check_cdr::<Twist>(&b));
                (b, r)
            }
            1 => {
                let b = apply(&rclpy(&msgs::TWIST_STAMPED), &ops, 4);
                let r = no_panic(&b, || check_cdr::<TwistStamped>(&b));
                (b, r)
            }
            2 => {
                let b = apply(&rclpy(&msgs::ODOMETRY), &ops, 4);
                let r = no_panic(&b, || check_cdr::<Odometry>(&b));
                (b, r)
            }
            3 => {
                let b = apply(&PoseStamped::planar(1.0, 2.0, 3.0, stamp, "m").to_cdr(), &ops, 4);
                let r = no_panic(&b, || check_cdr::<PoseStamped>(&b));
                (b, r)
            }
            _ => {
                let b = apply(&rclpy(&msgs::POSE_WITH_COVARIANCE_STAMPED), &ops, 4);
                let r = no_panic(&b, || check_cdr::<PoseWithCovarianceStamped>(&b));
                (b, r)
            }
        };
        prop_assert!(r.is_ok(), "{ops:?} ({}): {r:?}", hex(&b));
    }
}
