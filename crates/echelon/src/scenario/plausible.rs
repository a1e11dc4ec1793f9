//! The plausible range of every number in a scenario file, in one table
//! ([`PLAUSIBLE`]), for differential-drive robots from toy to industrial.
//!
//! A value the domain types accept (finite, positive, …) may still be absurd:
//! a look-ahead `l = 1e9` m, a mass of 10³⁰ kg. After the build has checked
//! each value against its own rules, every number in the document is checked
//! against its row: outside the row's `refuse` range it is refused at its
//! `file:line:column`; outside the narrower `warn` range (where a row has one)
//! the run goes ahead with a warning ([`crate::scenario::Run::warnings`]).
//! Non-finite values are left to the domain rules (which refuse them, except
//! where infinity means "unlimited", as `range = inf`).

use super::locate::{FieldPath, Locator, Seg};
use super::schema::ScenarioFile;
use crate::error::ScenarioError;

/// One row of [`PLAUSIBLE`]: the fields whose path ends in `pattern`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plausible {
    /// The end of a field path, dotted: `*` stands for any key (a robot's
    /// name, the reference's kind), `a|b` for either key, `[]` for any array index
    /// (`safety.obstacles[].r`). An agent's own tables match too
    /// (`control.ke` matches `agents[2].control.ke`).
    pub pattern: &'static str,
    /// Unit of the field (empty: a pure number).
    pub unit: &'static str,
    /// Refused outside `[lo, hi]`.
    pub refuse: (f64, f64),
    /// Warned about outside `[lo, hi]` (within `refuse`): unusual but possibly
    /// meant.
    pub warn: Option<(f64, f64)>,
}

const fn row(pattern: &'static str, unit: &'static str, lo: f64, hi: f64) -> Plausible {
    Plausible {
        pattern,
        unit,
        refuse: (lo, hi),
        warn: None,
    }
}

const fn warned(
    pattern: &'static str,
    unit: &'static str,
    refuse: (f64, f64),
    warn: (f64, f64),
) -> Plausible {
    Plausible {
        pattern,
        unit,
        refuse,
        warn: Some(warn),
    }
}

/// Largest plausible `|x|`, `|y|` of a position, m (1000 km).
const POSITION: f64 = 1e6;
/// Largest plausible speed, m/s: a reference's, which waypoints may not
/// exceed on average either ([`crate::reference::Waypoints::MAX_SPEED`]).
const SPEED: f64 = crate::reference::Waypoints::MAX_SPEED;
/// Largest plausible turn rate, rad/s.
const TURN_RATE: f64 = 1000.0;

/// The fields of every pose (`PoseSpec`): a start, a frame's origin.
const POSE_X: &str = "start|frame_origin|odom_origin.x";
const POSE_Y: &str = "start|frame_origin|odom_origin.y";
const POSE_THETA: &str = "start|frame_origin|odom_origin.theta";
const POSE_THETA_DEG: &str = "start|frame_origin|odom_origin.theta_deg";

/// The plausible ranges, one row per field (the first row that matches a
/// field's path applies). `docs/scenario-format.md` ("Plausible ranges")
/// lists the same table.
pub const PLAUSIBLE: &[Plausible] = &[
    // [sim], [log]
    warned("sim.dt", "s", (1e-6, 1.0), (1e-6, 0.1)),
    row("sim.duration", "s", 0.0, 1e6),
    row("sim.controller_period", "s", 1e-6, 1.0),
    row("sim.bounds.speed", "m/s", 1e-3, 1e4),
    row("sim.bounds.turn_rate", "rad/s", 1e-3, 1e5),
    row("sim.bounds.distance", "m", 1e-3, 1e9),
    row("log.dt", "s", 0.0, 1e6),
    // [control] and an agent's control: gains are only warned about below
    // 1e15, so that a run meant to diverge (`ke = 1e12`) can be run.
    warned("control.ke", "", (1e-15, 1e15), (1e-3, 1e4)),
    warned("control.kz", "", (1e-15, 1e15), (1e-3, 1e4)),
    row("control.l", "m", 1e-4, 10.0),
    // [robots.NAME]: torque-driven
    row("robots.*.mass", "kg", 0.05, 5000.0),
    row("robots.*.linear_friction", "kg/s", 0.0, 1e5),
    row("robots.*.inertia", "kg m²", 1e-6, 1e4),
    row("robots.*.angular_friction", "kg m²/s", 0.0, 1e4),
    row("robots.*.torque_limit", "N m", 1e-4, 1e5),
    // [robots.NAME]: both drives
    row("robots.*.half_wheelbase", "m", 0.005, 5.0),
    row("robots.*.wheel_radius", "m", 0.005, 2.0),
    // [robots.NAME]: velocity bases
    row("robots.*.tau_v", "s", 0.0, 10.0),
    row("robots.*.tau_omega", "s", 0.0, 10.0),
    row("robots.*.v_max", "m/s", 1e-4, SPEED),
    row("robots.*.omega_max", "rad/s", 1e-3, TURN_RATE),
    row("robots.*.a_max", "m/s²", 1e-3, 1000.0),
    row("robots.*.alpha_max", "rad/s²", 1e-3, 1e4),
    // [reference.KIND]
    row("reference.*.speed", "m/s", 0.0, SPEED),
    row("reference.*.turn_rate", "rad/s", -100.0, 100.0),
    row("lemniscate.a", "m", 1e-3, 1e4),
    row("lemniscate.c", "rad/s", -100.0, 100.0),
    row("lemniscate.center[]", "m", -POSITION, POSITION),
    row("cubic.scale", "m/s³", -100.0, 100.0),
    row("cubic.t_switch", "s", -1e6, 1e6),
    row("waypoints.points[][]", "s or m", -1e6, 1e6),
    // poses: a reference's start, an agent's, and the frames' origins
    // (`[fixes]`' frame_origin, an agent's odom_origin)
    row(POSE_X, "m", -POSITION, POSITION),
    row(POSE_Y, "m", -POSITION, POSITION),
    row(POSE_THETA, "rad", -1000.0, 1000.0),
    row(POSE_THETA_DEG, "°", -57_000.0, 57_000.0),
    row("start.v", "m/s", -SPEED, SPEED),
    row("start.omega", "rad/s", -TURN_RATE, TURN_RATE),
    // [[agents]]
    row("offset.x", "m", -1000.0, 1000.0),
    row("offset.y", "m", -1000.0, 1000.0),
    // [odometry] and an agent's odometry
    row("odometry.period", "s", 1e-6, 1.0),
    row("odometry.ticks_per_rev", "", 1.0, 1e8),
    row("odometry.zeta", "m", 0.0, 1.0),
    warned("odometry.wheel_diameter_ratio", "", (0.5, 2.0), (0.9, 1.1)),
    warned("odometry.wheelbase_ratio", "", (0.5, 2.0), (0.9, 1.1)),
    row("odometry.slip", "m²/m", 0.0, 1.0),
    row("odometry.speed_noise", "m/s", 0.0, 10.0),
    row("odometry.turn_rate_noise", "rad/s", 0.0, 10.0),
    // [fixes] and an agent's fixes
    row("fixes.every_steps", "", 1.0, 1e9),
    row("fixes.period", "s", 1e-6, 1e6),
    row("fixes.position_noise", "m", 0.0, 1000.0),
    row("fixes.heading_noise", "rad", 0.0, std::f64::consts::PI),
    row("fixes.latency", "s", 0.0, 60.0),
    row("fixes.timeout", "s", 1e-3, 3600.0),
    row("fixes.tolerance", "m", 1e-4, 100.0),
    // [safety] and an agent's safety
    row("safety.radius", "m", 1e-3, 100.0),
    row("safety.gain", "1/s", 1e-3, 1e4),
    row("safety.range", "m", 1e-3, 1e6),
    row("obstacles[].x", "m", -POSITION, POSITION),
    row("obstacles[].y", "m", -POSITION, POSITION),
    row("obstacles[].r", "m", 1e-3, 1e4),
    // [fleet] and an agent's link_loss, ros2 (checked by `Scenario::fleet`)
    row("fleet.reference_rate", "Hz", 0.1, 1e4),
    row("fleet.control_rate", "Hz", 0.1, 1e4),
    row("fleet.state_rate", "Hz", 0.1, 1e4),
    row("fleet.link_timeout", "s", 1e-3, 3600.0),
    row("fleet.stale_after", "s", 1e-3, 3600.0),
    row("fleet.operator_heartbeat", "s", 1e-2, 3600.0),
    row("link_loss.hold", "s", 0.0, 3600.0),
    row("link_loss.decel", "m/s²", 1e-3, 100.0),
    row("ros2.odom_timeout", "s", 1e-3, 3600.0),
    row("ros2.cmd_vel_timeout", "s", 1e-3, 3600.0),
    row("ros2.odom_rate", "Hz", 0.1, 1e4),
];

/// Which part of the document a check covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Part {
    /// What the simulator uses: everything but the fleet's settings.
    Simulation,
    /// `[fleet]` and the agents' `link_loss`, `ros2`.
    Fleet,
}

/// Whether `path` is one of the fleet's settings.
fn is_fleet(path: &FieldPath) -> bool {
    match path.0.first() {
        Some(Seg::Key(k)) if k == "fleet" => true,
        Some(Seg::Key(k)) if k == "agents" => {
            matches!(path.0.get(2), Some(Seg::Key(k)) if k == "link_loss" || k == "ros2")
        }
        _ => false,
    }
}

/// Checks every number of `file` in `part` against [`PLAUSIBLE`]: the first
/// value outside its `refuse` range is refused at its place (`at` locates
/// it); the values outside their `warn` range are returned as warnings, each
/// one line naming its place as an error would.
pub(super) fn check(
    file: &ScenarioFile,
    at: &Locator<'_>,
    part: Part,
) -> Result<Vec<String>, ScenarioError> {
    // The document as built (command-line overrides applied); its field names
    // are the file's.
    let Ok(doc) = toml::Table::try_from(file) else {
        return Ok(Vec::new());
    };
    let mut numbers = Vec::new();
    numbers_in_table(&doc, &mut FieldPath::default(), &mut numbers);
    let mut warnings = Vec::new();
    for (path, v) in numbers {
        if !v.is_finite() || is_fleet(&path) != (part == Part::Fleet) {
            continue;
        }
        let Some(p) = row_of(&path) else { continue };
        let unit = if p.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", p.unit)
        };
        let (lo, hi) = p.refuse;
        if !(lo..=hi).contains(&v) {
            return Err(at.error(
                &path,
                format!(
                    "{}{unit} is outside the plausible range {} to {}{unit}",
                    num(v),
                    num(lo),
                    num(hi)
                ),
            ));
        }
        if let Some((lo, hi)) = p.warn
            && !(lo..=hi).contains(&v)
        {
            let e = at.error(
                &path,
                format!(
                    "{}{unit} is outside the usual range {} to {}{unit} (allowed; the run may be stiff or diverge)",
                    num(v),
                    num(lo),
                    num(hi)
                ),
            );
            warnings.push(e.to_string());
        }
    }
    Ok(warnings)
}

/// The row that applies to `path`, if any.
pub(super) fn row_of(path: &FieldPath) -> Option<&'static Plausible> {
    PLAUSIBLE.iter().find(|p| matches(p.pattern, path))
}

/// Whether `path` ends in `pattern` ([`Plausible::pattern`]).
fn matches(pattern: &str, path: &FieldPath) -> bool {
    let mut want = Vec::new();
    for part in pattern.split('.') {
        let key = part.trim_end_matches("[]");
        want.push(Some(key));
        for _ in 0..(part.len() - key.len()) / 2 {
            want.push(None);
        }
    }
    if want.len() > path.0.len() {
        return false;
    }
    want.iter()
        .rev()
        .zip(path.0.iter().rev())
        .all(|(w, seg)| match (w, seg) {
            (Some("*"), Seg::Key(_)) | (None, Seg::Index(_)) => true,
            (Some(w), Seg::Key(k)) => w.split('|').any(|w| w == k),
            _ => false,
        })
}

/// Every number of a document with its path.
fn numbers_in_table(t: &toml::Table, path: &mut FieldPath, out: &mut Vec<(FieldPath, f64)>) {
    for (k, v) in t {
        path.0.push(Seg::Key(k.clone()));
        numbers_in(v, path, out);
        path.0.pop();
    }
}

fn numbers_in(v: &toml::Value, path: &mut FieldPath, out: &mut Vec<(FieldPath, f64)>) {
    match v {
        toml::Value::Float(x) => out.push((path.clone(), *x)),
        // Integers as floats: the rows' bounds are far within 2⁵³.
        #[allow(clippy::cast_precision_loss)]
        toml::Value::Integer(n) => out.push((path.clone(), *n as f64)),
        toml::Value::Table(t) => numbers_in_table(t, path, out),
        toml::Value::Array(items) => {
            for (i, item) in items.iter().enumerate() {
                path.0.push(Seg::Index(i));
                numbers_in(item, path, out);
                path.0.pop();
            }
        }
        _ => {}
    }
}

pub(super) use crate::error::num;

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // tests fail loudly by design

    use super::*;

    fn path(s: &str) -> FieldPath {
        let mut p = FieldPath::default();
        for part in s.split('.') {
            let key = part.trim_end_matches("[1]");
            p = p.key(key);
            if key.len() != part.len() {
                p = p.index(0);
            }
        }
        p
    }

    #[test]
    fn patterns_match_the_end_of_a_path() {
        let row = |s: &str| row_of(&path(s)).map(|p| p.pattern);
        assert_eq!(row("robots.heavy.mass"), Some("robots.*.mass"));
        assert_eq!(row("control.ke"), Some("control.ke"));
        assert_eq!(row("agents[1].control.ke"), Some("control.ke"));
        assert_eq!(row("agents[1].start.x"), Some(POSE_X));
        assert_eq!(row("reference.circle.start.theta"), Some(POSE_THETA));
        assert_eq!(row("fixes.frame_origin.y"), Some(POSE_Y));
        assert_eq!(row("agents[0].odom_origin.theta_deg"), Some(POSE_THETA_DEG));
        assert_eq!(row("agents[0].origin.x"), None);
        assert_eq!(row("reference.line.speed"), Some("reference.*.speed"));
        assert_eq!(row("safety.obstacles[1].r"), Some("obstacles[].r"));
        assert_eq!(row("agents[1].safety.gain"), Some("safety.gain"));
        assert_eq!(row("seed"), None);
        assert_eq!(row("agents[1].leader"), None);
        let mut p = path("reference.waypoints.points[1]");
        p = p.index(2);
        assert_eq!(row_of(&p).map(|r| r.pattern), Some("waypoints.points[][]"));
        assert!(is_fleet(&path("agents[1].link_loss.hold")));
        assert!(is_fleet(&path("fleet.control_rate")));
        assert!(!is_fleet(&path("agents[1].control.ke")));
    }

    #[test]
    fn every_row_is_sane() {
        for p in PLAUSIBLE {
            let (lo, hi) = p.refuse;
            assert!(lo < hi, "{}", p.pattern);
            if let Some((wlo, whi)) = p.warn {
                assert!(lo <= wlo && wlo < whi && whi <= hi, "{}", p.pattern);
            }
            // Each pattern is reachable: no earlier row shadows it.
            let first = PLAUSIBLE.iter().find(|q| q.pattern == p.pattern);
            assert_eq!(first, Some(p), "{} twice", p.pattern);
        }
    }

    /// Every number a scenario can hold, each field set at least once.
    const EVERY_FIELD: &str = r#"
[sim]
duration = 1.0
dt = 0.01
controller_period = 0.01
bounds = { speed = 100.0, turn_rate = 100.0, distance = 1e6 }
[log]
dt = 0.01
[control]
ke = 1.5
kz = 10.0
l = 0.05
[robots.t]
preset = "agent1"
mass = 27.0
linear_friction = 180.0
inertia = 1.42
angular_friction = 9.47
half_wheelbase = 0.23
wheel_radius = 0.101
torque_limit = 5.0
[robots.v]
drive = "velocity"
tau_v = 0.1
tau_omega = 0.1
v_max = 0.5
omega_max = 3.0
a_max = 1.0
alpha_max = 5.0
[reference.lemniscate]
a = 2.0
c = 0.1
center = [0.0, 0.0]
[[agents]]
robot = "t"
start = { x = 0.0, y = 0.0, theta = 0.0, v = 0.0, omega = 0.0 }
leader = "reference"
offset = { x = 0.5, y = 0.0 }
control = { ke = 1.5, kz = 10.0, l = 0.05 }
odometry = { period = 0.01, zeta = 0.0 }
fixes = { period = 1.0 }
safety = { gain = 1.0, range = 2.0 }
link_loss = { hold = 1.0, decel = 0.1 }
ros2 = { odom_timeout = 0.5, cmd_vel_timeout = 0.5, odom_rate = 50.0 }
[[agents]]
robot = "v"
start = { x = 0.0, y = 1.0, theta_deg = 0.0 }
leader = "reference"
mode = "tracking"
odom_origin = { x = 0.0, y = 1.0, theta = 0.0 }
fixes = { source = "pose", timeout = 1.0, tolerance = 0.05, frame_origin = { x = 0.0, y = 0.0, theta_deg = 0.0 } }
[[agents]]
robot = "v"
start = { x = 0.0, y = 2.0, theta = 0.0 }
leader = "reference"
odom_origin = { x = 0.0, y = 2.0, theta_deg = 0.0 }
fixes = { frame_origin = { x = 0.0, y = 0.0, theta = 0.0 } }
[odometry]
period = 0.01
ticks_per_rev = 1024
zeta = 1e-5
wheel_diameter_ratio = 1.0
wheelbase_ratio = 1.0
slip = 0.0
speed_noise = 0.0
turn_rate_noise = 0.0
[fixes]
every_steps = 100
position_noise = 0.0
heading_noise = 0.0
latency = 0.0
[safety]
radius = 0.2
gain = 1.0
range = 2.0
obstacles = [{ x = 5.0, y = 5.0, r = 0.2 }]
[fleet]
reference_rate = 50.0
state_rate = 10.0
control_rate = 100.0
link_timeout = 0.2
stale_after = 0.5
operator_heartbeat = 1.0
[fleet.link_loss]
hold = 1.0
decel = 0.1
[fleet.ros2]
odom_timeout = 0.5
cmd_vel_timeout = 0.5
odom_rate = 50.0
"#;

    /// The other references' numbers.
    const REFERENCES: [&str; 4] = [
        "[reference.circle]\nspeed = 0.5\nturn_rate = 0.1\nstart = { x = 0.0, y = 0.0, theta = 0.0 }\n",
        "[reference.line]\nspeed = 0.5\nstart = { x = 0.0, y = 0.0, theta_deg = 0.0 }\n",
        "[reference.cubic]\nscale = 0.0625\nt_switch = 4.0\n",
        "[reference.waypoints]\npoints = [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]]\n",
    ];

    /// Integers that are names or seeds, not quantities.
    const NOT_QUANTITIES: [&str; 3] = ["seed", "leader", "domain_id"];

    #[test]
    fn every_number_a_scenario_can_hold_has_a_row() {
        let lemniscate = "[reference.lemniscate]\na = 2.0\nc = 0.1\ncenter = [0.0, 0.0]\n";
        let mut sources = vec![EVERY_FIELD.to_owned()];
        for r in REFERENCES {
            sources.push(EVERY_FIELD.replace(lemniscate, r));
        }
        let mut seen = Vec::new();
        for src in &sources {
            let file: ScenarioFile = toml::from_str(src).unwrap();
            let doc = toml::Table::try_from(&file).unwrap();
            let mut numbers = Vec::new();
            numbers_in_table(&doc, &mut FieldPath::default(), &mut numbers);
            for (path, v) in numbers {
                let last = path.to_string();
                if NOT_QUANTITIES.iter().any(|k| last.ends_with(k)) {
                    continue;
                }
                let row = row_of(&path).unwrap_or_else(|| panic!("{path} has no row"));
                let (lo, hi) = row.refuse;
                assert!((lo..=hi).contains(&v), "{path} = {v}");
                seen.push(row.pattern);
            }
        }
        // And every row is used by some field.
        for p in PLAUSIBLE {
            assert!(seen.contains(&p.pattern), "{} matches no field", p.pattern);
        }
    }

    #[test]
    fn numbers_are_written_readably() {
        assert_eq!(num(1e30), "1e30");
        assert_eq!(num(5000.0), "5000");
        assert_eq!(num(0.05), "0.05");
        assert_eq!(num(1e-4), "1e-4");
        assert_eq!(num(-1e6), "-1e6");
        assert_eq!(num(0.0), "0");
    }
}
