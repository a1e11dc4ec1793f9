//! The wire format: versioned, fixed-layout little-endian messages.
//!
//! Every message starts with the same 24-byte header:
//!
//! | offset | type | field |
//! |---|---|---|
//! | 0 | u8 | magic `0xEC` |
//! | 1 | u8 | format version, [`VERSION`] |
//! | 2 | u8 | kind: 1 reference, 2 robot state |
//! | 3 | u8 | reference: 0; state: link status ([`LinkStatus`]) |
//! | 4 | u32 | source: a random number drawn when the sender starts (a restart is a new source) |
//! | 8 | u64 | sequence number, from 0, +1 per message of this source |
//! | 16 | f64 | sender time `t`, fleet seconds |
//!
//! then the kind's payload (see [`Reference`] and [`RobotState`]; a state
//! may end with an optional odometry block, [`OdometryState`]).
//! All floats must be finite. A message whose length, magic, kind, flags,
//! reserved bytes or floats are wrong is *malformed*; a header with the
//! magic and another version is *wrong-version* (nothing after the version
//! byte is read: another version may lay it out otherwise). Neither ever
//! panics the receiver, and nothing of the message is kept: an accepted
//! message is exactly the encoding of what it decoded to, no bit ignored.
//! (A field that must be zero must be `+0.0`: `-0.0` is another encoding.)

use echelon::control::LeaderMotion;
use echelon::model::{Input, State, Torques};
use echelon::sample::{AgentSample, VelocitySample};
use echelon::sim::AgentOutput;

/// First byte of every message.
pub const MAGIC: u8 = 0xEC;
/// Format version written and accepted (2: a state carries its velocity
/// base's command; 3: and its position uncertainty `σ`, and optionally its
/// raw odometry: a state without the block is as before, so version 3
/// senders that never send it are still understood).
pub const VERSION: u8 = 3;
/// Header length, bytes.
pub const HEADER_LEN: usize = 24;
/// A reference message's length, bytes (header + 8 f64).
pub const REFERENCE_LEN: usize = HEADER_LEN + 8 * 8;
/// A state message's length, bytes (header + agent u32 + drive flags u8 +
/// 3 reserved + 26 f64).
pub const STATE_LEN: usize = HEADER_LEN + 8 + 26 * 8;
/// A state message's length with its odometry block, bytes ([`STATE_LEN`]
/// + 5 f64: raw `x, y, θ`, `age`, `fix_age`).
pub const STATE_ODOMETRY_LEN: usize = STATE_LEN + 5 * 8;

/// Drive flags of a state: a velocity base's state.
const FLAG_VELOCITY: u8 = 1;
/// Drive flags of a state: the base's speed limits cut the command.
const FLAG_SATURATED: u8 = 2;
/// Drive flags of a state: the odometry block follows.
const FLAG_ODOMETRY: u8 = 4;
/// Drive flags of a state: the odometry block's `fix_age` is set.
const FLAG_FIX_AGE: u8 = 8;
/// The drive flags that say what the velocity fields hold.
const DRIVE_BITS: u8 = FLAG_VELOCITY | FLAG_SATURATED;
/// Every drive flag this version defines: any other bit is from another
/// version, or corruption.
const KNOWN_FLAGS: u8 = DRIVE_BITS | FLAG_ODOMETRY | FLAG_FIX_AGE;
/// The bytes of a state after its drive flags, reserved (zero).
const STATE_RESERVED: std::ops::Range<usize> = HEADER_LEN + 5..HEADER_LEN + 8;

const KIND_REFERENCE: u8 = 1;
const KIND_STATE: u8 = 2;

/// Why a message was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// Wrong length, magic, kind, agent or a non-finite number.
    #[error("malformed message: {0}")]
    Malformed(&'static str),
    /// A well-formed header carrying another format version.
    #[error("format version {0}, expected {VERSION}")]
    WrongVersion(u8),
}

/// The common header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Header {
    /// Random per sender start.
    pub source: u32,
    /// Sequence number of this source.
    pub seq: u64,
}

/// A robot's link to its leader, as it reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LinkStatus {
    /// No leader message yet: the robot stands still and its clock is not synced.
    #[default]
    Waiting = 0,
    /// Fresh leader messages: normal operation.
    Tracking = 1,
    /// Lost; `extrapolate` is advancing the last reference.
    Extrapolating = 2,
    /// Lost; the leader motion is brought to rest (`stop`, or `extrapolate`
    /// past its hold time).
    Stopping = 3,
    /// A fleet stop is in force (`fleet stop`): the robot commands zero
    /// until a resume, whatever its link.
    Stopped = 4,
    /// A watchdog holds it ([`crate::robot::Watchdog`]): its odometry is
    /// stale or the operator's heartbeat is lost; it commands zero until
    /// the watchdog is satisfied again.
    Held = 5,
}

impl LinkStatus {
    /// Its name in logs.
    pub fn name(self) -> &'static str {
        match self {
            LinkStatus::Waiting => "waiting",
            LinkStatus::Tracking => "tracking",
            LinkStatus::Extrapolating => "extrapolating",
            LinkStatus::Stopping => "stopping",
            LinkStatus::Stopped => "stopped",
            LinkStatus::Held => "held",
        }
    }

    fn from_u8(b: u8) -> Option<LinkStatus> {
        Some(match b {
            0 => LinkStatus::Waiting,
            1 => LinkStatus::Tracking,
            2 => LinkStatus::Extrapolating,
            3 => LinkStatus::Stopping,
            4 => LinkStatus::Stopped,
            5 => LinkStatus::Held,
            _ => return None,
        })
    }
}

/// A reference sample: payload `p_d[2], ṗ_d[2], p̈_d[2], V_d, ω_d` (m, m/s,
/// m/s², m/s, rad/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reference {
    /// Sender time, s.
    pub t: f64,
    /// `p_d`, `ṗ_d`, `p̈_d`.
    pub motion: LeaderMotion,
    /// `V_d`, m/s.
    pub speed: f64,
    /// `ω_d`, rad/s.
    pub turn_rate: f64,
}

/// A ROS 2 robot's own odometry as its state was published: what the
/// collector keeps beside the world pose (`odometry` in the state JSON:
/// `{"raw": [x, y, θ], "age": s, "fix_age": s | null}`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct OdometryState {
    /// The pose in the robot's own odom frame (before the odom → world
    /// map), heading unwrapped, `[x, y, θ]` (m, m, rad).
    pub raw: [f64; 3],
    /// Age of the newest odometry sample when the state was published, s (≥ 0).
    pub age: f64,
    /// Age of the newest accepted fix then, s (≥ 0); `None`: no fix yet,
    /// or the robot takes none.
    pub fix_age: Option<f64>,
}

/// A robot's state with what its controller did: its [`AgentSample`]
/// ([`RobotState::sample`]) and what the wire adds (link status,
/// accelerations, the leader motion used). Payload after the header:
/// `agent: u32` (from 1), drive flags `u8` (bit 0: a velocity base, bit 1:
/// its speed limits cut the command; bits 4 to 7 are 0), 3 reserved bytes
/// (0; a state with another flag bit or reserved byte is malformed: another
/// version's, or corrupt), then the f64s
/// `x, y, θ, v, ω, v̇, ω̇, e_x, e_y, z_x, z_y, u1, u2, τ_r, τ_l,
/// p_d[2], ṗ_d[2], p̈_d[2], v*, ω*, v_applied, ω_applied, σ` (`v*` to
/// `ω_applied` 0 for a torque-driven robot; `σ ≥ 0`). With drive flag bit 2
/// an odometry block follows ([`OdometryState`]): the f64s `x_raw, y_raw,
/// θ_raw, age, fix_age` (`fix_age` meaningful with bit 3, else 0; ages ≥ 0).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RobotState {
    /// Sender time, s.
    pub t: f64,
    /// Agent number, from 1.
    pub agent: u32,
    /// Link status when this state was published.
    pub link: LinkStatus,
    /// The state.
    pub state: State,
    /// `v̇`, m/s² (so followers form `p̈_d`, control-law.md).
    pub dv: f64,
    /// `ω̇`, rad/s².
    pub domega: f64,
    /// Tracking error `e` (eq. 7), m.
    pub e: [f64; 2],
    /// Backstepping error `z` (eq. 10), m/s.
    pub z: [f64; 2],
    /// Applied input.
    pub u: Input,
    /// Applied wheel torques.
    pub tau: Torques,
    /// The leader motion the law used.
    pub leader: LeaderMotion,
    /// A velocity base's command (`None`: a torque-driven robot).
    pub velocity: Option<VelocitySample>,
    /// The standard deviation of its position estimate along its most
    /// uncertain axis, m (0: exact, as a simulated plant, or unknown): what
    /// neighbours' safety filters widen the pair's radius by
    /// (`docs/safety.md`, "Uncertain positions").
    pub sigma: f64,
    /// A ROS 2 robot's raw odometry (`None`: a simulated plant, or no
    /// odometry yet).
    pub odometry: Option<OdometryState>,
}

impl RobotState {
    /// The sample it carries (heading wrapped). A fleet robot acts on its
    /// true state (no odometry model in the fleet): what it saw is what it is.
    pub fn sample(&self) -> AgentSample {
        let output = AgentOutput {
            e: self.e,
            z: self.z,
            e_hat: self.e,
            z_hat: self.z,
            command: self.u,
            u: self.u,
            tau: self.tau,
            velocity: None,
        };
        AgentSample {
            velocity: self.velocity,
            ..AgentSample::new(self.t, self.agent, &self.state, &output)
        }
    }
}

/// A decoded message.
#[derive(Debug, Clone, Copy, PartialEq)]
// A state is larger than a reference; boxing it would allocate per
// message on the receive path, which must not.
#[allow(clippy::large_enum_variant)]
pub enum Message {
    /// From the leader.
    Reference(Header, Reference),
    /// From a robot.
    State(Header, RobotState),
}

fn put_header(buf: &mut Vec<u8>, kind: u8, flags: u8, h: Header, t: f64) {
    buf.clear();
    buf.extend_from_slice(&[MAGIC, VERSION, kind, flags]);
    buf.extend_from_slice(&h.source.to_le_bytes());
    buf.extend_from_slice(&h.seq.to_le_bytes());
    buf.extend_from_slice(&t.to_le_bytes());
}

fn put_f64s(buf: &mut Vec<u8>, values: &[f64]) {
    for v in values {
        buf.extend_from_slice(&v.to_le_bytes());
    }
}

/// Encodes a reference sample into `buf` (cleared first).
pub fn encode_reference(buf: &mut Vec<u8>, h: Header, r: &Reference) {
    put_header(buf, KIND_REFERENCE, 0, h, r.t);
    let m = &r.motion;
    put_f64s(
        buf,
        &[
            m.p[0],
            m.p[1],
            m.dp[0],
            m.dp[1],
            m.ddp[0],
            m.ddp[1],
            r.speed,
            r.turn_rate,
        ],
    );
}

/// Encodes a robot state into `buf` (cleared first).
pub fn encode_state(buf: &mut Vec<u8>, h: Header, s: &RobotState) {
    put_header(buf, KIND_STATE, s.link as u8, h, s.t);
    buf.extend_from_slice(&s.agent.to_le_bytes());
    let mut flags = s.velocity.map_or(0, |v| {
        FLAG_VELOCITY | if v.sat { FLAG_SATURATED } else { 0 }
    });
    if let Some(o) = &s.odometry {
        flags |= FLAG_ODOMETRY | if o.fix_age.is_some() { FLAG_FIX_AGE } else { 0 };
    }
    buf.extend_from_slice(&[flags, 0, 0, 0]);
    let (x, l) = (&s.state, &s.leader);
    let c = s.velocity.unwrap_or_default();
    put_f64s(
        buf,
        &[
            x.x,
            x.y,
            x.theta,
            x.v,
            x.omega,
            s.dv,
            s.domega,
            s.e[0],
            s.e[1],
            s.z[0],
            s.z[1],
            s.u.u1,
            s.u.u2,
            s.tau.right,
            s.tau.left,
            l.p[0],
            l.p[1],
            l.dp[0],
            l.dp[1],
            l.ddp[0],
            l.ddp[1],
            c.v_cmd,
            c.omega_cmd,
            c.v_applied,
            c.omega_applied,
            s.sigma,
        ],
    );
    if let Some(o) = &s.odometry {
        put_f64s(
            buf,
            &[
                o.raw[0],
                o.raw[1],
                o.raw[2],
                o.age,
                o.fix_age.unwrap_or(0.0),
            ],
        );
    }
}

/// Reads `N` finite little-endian f64s from `b` (which holds exactly `8N` bytes).
fn f64s<const N: usize>(b: &[u8]) -> Result<[f64; N], DecodeError> {
    let mut out = [0.0; N];
    for (o, chunk) in out.iter_mut().zip(b.chunks_exact(8)) {
        let mut a = [0u8; 8];
        a.copy_from_slice(chunk);
        *o = f64::from_le_bytes(a);
        if !o.is_finite() {
            return Err(DecodeError::Malformed("non-finite number"));
        }
    }
    Ok(out)
}

/// The odometry block of a state with drive flags `flags` (`b`: its 40 bytes).
fn odometry_block(b: &[u8], flags: u8) -> Result<OdometryState, DecodeError> {
    let o = f64s::<5>(b)?;
    if o[3] < 0.0 || o[4] < 0.0 {
        return Err(DecodeError::Malformed("a negative odometry age"));
    }
    let fix_age = match flags & FLAG_FIX_AGE != 0 {
        true => Some(o[4]),
        false if o[4].to_bits() == 0 => None,
        false => return Err(DecodeError::Malformed("a fix age without its flag")),
    };
    Ok(OdometryState {
        raw: [o[0], o[1], o[2]],
        age: o[3],
        fix_age,
    })
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    let mut a = [0u8; 4];
    a.copy_from_slice(&b[at..at + 4]);
    u32::from_le_bytes(a)
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(a)
}

/// Decodes one message, checking everything; never panics.
pub fn decode(b: &[u8]) -> Result<Message, DecodeError> {
    if b.len() < HEADER_LEN {
        return Err(DecodeError::Malformed("shorter than the header"));
    }
    if b[0] != MAGIC {
        return Err(DecodeError::Malformed("bad magic byte"));
    }
    if b[1] != VERSION {
        return Err(DecodeError::WrongVersion(b[1]));
    }
    let header = Header {
        source: u32_at(b, 4),
        seq: u64_at(b, 8),
    };
    let [t] = f64s::<1>(&b[16..24])?;
    match b[2] {
        KIND_REFERENCE => decode_reference(b, t).map(|r| Message::Reference(header, r)),
        KIND_STATE => decode_state(b, t).map(|s| Message::State(header, s)),
        _ => Err(DecodeError::Malformed("unknown kind")),
    }
}

/// The body of a reference message `b` (its header already checked) at
/// fleet time `t`.
#[inline]
fn decode_reference(b: &[u8], t: f64) -> Result<Reference, DecodeError> {
    if b.len() != REFERENCE_LEN {
        return Err(DecodeError::Malformed("wrong length for a reference"));
    }
    if b[3] != 0 {
        return Err(DecodeError::Malformed("reference flags must be 0"));
    }
    let v = f64s::<8>(&b[HEADER_LEN..])?;
    Ok(Reference {
        t,
        motion: LeaderMotion {
            p: [v[0], v[1]],
            dp: [v[2], v[3]],
            ddp: [v[4], v[5]],
        },
        speed: v[6],
        turn_rate: v[7],
    })
}

/// The body of a state message `b` (its header already checked) at fleet
/// time `t`: its drive flags decide its length and its optional blocks.
#[inline]
fn decode_state(b: &[u8], t: f64) -> Result<RobotState, DecodeError> {
    // The flags decide the length: a message too short to hold
    // them is malformed (it was an index out of bounds).
    let Some(&flags) = b.get(HEADER_LEN + 4) else {
        return Err(DecodeError::Malformed("wrong length for a state"));
    };
    if flags & !KNOWN_FLAGS != 0 {
        return Err(DecodeError::Malformed("unknown drive flags"));
    }
    let with_odometry = flags & FLAG_ODOMETRY != 0;
    let len = if with_odometry {
        STATE_ODOMETRY_LEN
    } else {
        STATE_LEN
    };
    if b.len() != len {
        return Err(DecodeError::Malformed("wrong length for a state"));
    }
    if b[STATE_RESERVED] != [0; 3] {
        return Err(DecodeError::Malformed("reserved bytes must be 0"));
    }
    let link = LinkStatus::from_u8(b[3]).ok_or(DecodeError::Malformed("unknown link status"))?;
    let agent = u32_at(b, HEADER_LEN);
    if agent == 0 {
        return Err(DecodeError::Malformed("agent numbers start at 1"));
    }
    let v = f64s::<26>(&b[HEADER_LEN + 8..STATE_LEN])?;
    if v[25] < 0.0 {
        return Err(DecodeError::Malformed("a negative position uncertainty"));
    }
    let odometry = match with_odometry {
        false if flags & FLAG_FIX_AGE != 0 => {
            return Err(DecodeError::Malformed("a fix age without odometry"));
        }
        false => None,
        true => Some(odometry_block(&b[STATE_LEN..], flags)?),
    };
    let velocity = velocity_block(&v, flags)?;
    Ok(RobotState {
        t,
        agent,
        link,
        state: State {
            x: v[0],
            y: v[1],
            theta: v[2],
            v: v[3],
            omega: v[4],
        },
        dv: v[5],
        domega: v[6],
        e: [v[7], v[8]],
        z: [v[9], v[10]],
        u: Input {
            u1: v[11],
            u2: v[12],
        },
        tau: Torques {
            right: v[13],
            left: v[14],
        },
        leader: LeaderMotion {
            p: [v[15], v[16]],
            dp: [v[17], v[18]],
            ddp: [v[19], v[20]],
        },
        velocity,
        sigma: v[25],
        odometry,
    })
}

/// The velocity sample of a state with numbers `v` and drive flags `flags`:
/// none on a torque base (whose velocity slots must be zero).
#[inline]
fn velocity_block(v: &[f64; 26], flags: u8) -> Result<Option<VelocitySample>, DecodeError> {
    match flags & !(FLAG_ODOMETRY | FLAG_FIX_AGE) {
        0 if v[21..25].iter().all(|x| x.to_bits() == 0) => Ok(None),
        0 => Err(DecodeError::Malformed(
            "a torque state with a velocity command",
        )),
        f if f & FLAG_VELOCITY != 0 => Ok(Some(VelocitySample {
            v_cmd: v[21],
            omega_cmd: v[22],
            v_applied: v[23],
            omega_applied: v[24],
            sat: f & FLAG_SATURATED != 0,
        })),
        _ => Err(DecodeError::Malformed(
            "a saturation flag without a velocity base",
        )),
    }
}

#[cfg(test)]
mod tests;
