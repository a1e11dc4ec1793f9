//! The three ROS 2 messages a differential-drive base speaks, with their
//! CDR encoding: `geometry_msgs/msg/Twist` and `geometry_msgs/msg/TwistStamped`
//! (commands on `cmd_vel`) and `nav_msgs/msg/Odometry` (on `odom`).
//!
//! Frames follow REP 103/105: the odometry pose is in `header.frame_id`
//! (`odom`), its twist in `child_frame_id` (`base_link`), x forward, z up,
//! yaw counter-clockwise. [`Quaternion::yaw`] and [`YawUnwrapper`] turn the
//! orientation into the continuous heading the control law needs.

use std::f64::consts::{PI, TAU};

use crate::cdr::{CdrError, CdrReader, CdrWriter};

/// A ROS 2 message type: its name and its RIHS01 type hash (the hash
/// rmw_zenoh puts in key expressions and liveliness tokens).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MessageType {
    /// `package/msg/Type`.
    pub name: &'static str,
    /// `RIHS01_` and 64 hex digits, as in the package's `share/<pkg>/msg/<Type>.json`.
    pub hash: &'static str,
}

impl MessageType {
    /// The DDS-mangled name rmw_zenoh uses in keys: `package::msg::dds_::Type_`.
    pub fn dds_name(&self) -> String {
        match self.name.rsplit_once('/') {
            Some((namespace, ty)) => format!("{}::dds_::{ty}_", namespace.replace('/', "::")),
            None => format!("dds_::{}_", self.name),
        }
    }
}

/// `geometry_msgs/msg/Twist` (Jazzy).
pub const TWIST: MessageType = MessageType {
    name: "geometry_msgs/msg/Twist",
    hash: "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
};
/// `geometry_msgs/msg/TwistStamped` (Jazzy).
pub const TWIST_STAMPED: MessageType = MessageType {
    name: "geometry_msgs/msg/TwistStamped",
    hash: "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64",
};
/// `nav_msgs/msg/Odometry` (Jazzy).
pub const ODOMETRY: MessageType = MessageType {
    name: "nav_msgs/msg/Odometry",
    hash: "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
};
/// `std_msgs/msg/Header` (Jazzy), part of the stamped types' hashes.
pub const HEADER: MessageType = MessageType {
    name: "std_msgs/msg/Header",
    hash: "RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01",
};

/// A ROS 2 message with a CDR little-endian encoding.
pub trait RosMessage: Sized {
    /// Name and type hash.
    const TYPE: MessageType;

    /// Writes the fields (the writer already holds the header).
    fn write_cdr(&self, w: &mut CdrWriter<'_>);

    /// Reads the fields after the header.
    fn read_cdr(r: &mut CdrReader<'_>) -> Result<Self, CdrError>;

    /// The first field holding a NaN or an infinity, if any.
    fn first_non_finite(&self) -> Option<&'static str>;

    /// Encodes into `buf` (cleared first; its allocation is reused).
    fn encode_into(&self, buf: &mut Vec<u8>) {
        let mut w = CdrWriter::new(buf);
        self.write_cdr(&mut w);
    }

    /// The CDR payload, header included.
    fn to_cdr(&self) -> Vec<u8> {
        let mut buf = Vec::new();
        self.encode_into(&mut buf);
        buf
    }

    /// Decodes a payload. Bytes after the message are ignored; NaN and
    /// infinities are kept (see [`RosMessage::from_cdr_finite`]).
    fn from_cdr(bytes: &[u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(bytes)?;
        Self::read_cdr(&mut r)
    }

    /// Decodes a payload and refuses any non-finite number with
    /// [`CdrError::NonFinite`] naming the field.
    fn from_cdr_finite(bytes: &[u8]) -> Result<Self, CdrError> {
        let msg = Self::from_cdr(bytes)?;
        match msg.first_non_finite() {
            Some(field) => Err(CdrError::NonFinite { field }),
            None => Ok(msg),
        }
    }
}

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds, `0..1_000_000_000`.
    pub nanosec: u32,
}

impl Time {
    /// From nanoseconds since the epoch of the clock (seconds saturate at the `i32` range).
    pub fn from_nanos(ns: i64) -> Time {
        let sec = ns.div_euclid(1_000_000_000);
        let nanosec = ns.rem_euclid(1_000_000_000) as u32;
        match i32::try_from(sec) {
            Ok(sec) => Time { sec, nanosec },
            Err(_) if sec < 0 => Time {
                sec: i32::MIN,
                nanosec: 0,
            },
            Err(_) => Time {
                sec: i32::MAX,
                nanosec: 999_999_999,
            },
        }
    }

    /// Nanoseconds.
    pub fn to_nanos(self) -> i64 {
        i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)
    }

    /// Seconds as a float.
    pub fn as_secs_f64(self) -> f64 {
        f64::from(self.sec) + f64::from(self.nanosec) * 1e-9
    }

    fn write(&self, w: &mut CdrWriter<'_>) {
        w.write_i32(self.sec);
        w.write_u32(self.nanosec);
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Time, CdrError> {
        Ok(Time {
            sec: r.read_i32("header.stamp.sec")?,
            nanosec: r.read_u32("header.stamp.nanosec")?,
        })
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Header {
    /// Time of the data.
    pub stamp: Time,
    /// Coordinate frame (`odom`, `base_link`).
    pub frame_id: String,
}

impl Header {
    fn write(&self, w: &mut CdrWriter<'_>) {
        self.stamp.write(w);
        w.write_string(&self.frame_id);
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Header, CdrError> {
        let stamp = Time::read(r)?;
        let frame_id = r.read_string("header.frame_id")?.to_owned();
        Ok(Header { stamp, frame_id })
    }
}

/// `geometry_msgs/msg/Vector3` (and `Point`, which has the same layout).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Vector3 {
    /// x, m or m/s or rad/s.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

impl Vector3 {
    fn write(&self, w: &mut CdrWriter<'_>) {
        w.write_f64(self.x);
        w.write_f64(self.y);
        w.write_f64(self.z);
    }

    fn read(r: &mut CdrReader<'_>, field: &'static str) -> Result<Vector3, CdrError> {
        Ok(Vector3 {
            x: r.read_f64(field)?,
            y: r.read_f64(field)?,
            z: r.read_f64(field)?,
        })
    }

    fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.z.is_finite()
    }
}

/// `geometry_msgs/msg/Quaternion` (x, y, z, w; identity `0 0 0 1`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Quaternion {
        Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

impl Quaternion {
    /// The rotation by `yaw` (rad, counter-clockwise) about z.
    pub fn from_yaw(yaw: f64) -> Quaternion {
        let (s, c) = (0.5 * yaw).sin_cos();
        Quaternion {
            x: 0.0,
            y: 0.0,
            z: s,
            w: c,
        }
    }

    /// Yaw (rad, in `[-π, π]`) of the z-y'-x'' (REP 103) Euler decomposition:
    /// `atan2(2(wz + xy), w² + x² − y² − z²)`. The expression is homogeneous,
    /// so a quaternion that is not normalised gives the same yaw.
    pub fn yaw(&self) -> f64 {
        let Quaternion { x, y, z, w } = *self;
        (2.0 * (w * z + x * y)).atan2(w * w + x * x - y * y - z * z)
    }

    fn write(&self, w: &mut CdrWriter<'_>) {
        w.write_f64(self.x);
        w.write_f64(self.y);
        w.write_f64(self.z);
        w.write_f64(self.w);
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Quaternion, CdrError> {
        const F: &str = "pose.pose.orientation";
        Ok(Quaternion {
            x: r.read_f64(F)?,
            y: r.read_f64(F)?,
            z: r.read_f64(F)?,
            w: r.read_f64(F)?,
        })
    }

    fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.z.is_finite() && self.w.is_finite()
    }
}

/// Wraps an angle into `[-π, π)`.
pub fn wrap_angle(a: f64) -> f64 {
    a - TAU * ((a + PI) / TAU).floor()
}

/// Turns a sequence of wrapped yaws (`[-π, π]`) into a continuous heading:
/// each output differs from the previous output by the wrapped difference of
/// the inputs, so a robot turning through ±π keeps counting.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct YawUnwrapper {
    last: Option<(f64, f64)>,
}

impl YawUnwrapper {
    /// An unwrapper whose first output equals its first input.
    pub fn new() -> YawUnwrapper {
        YawUnwrapper::default()
    }

    /// The continuous heading for `yaw`. A non-finite `yaw` is returned
    /// unchanged and leaves the state as it was (callers refuse it first).
    pub fn unwrap(&mut self, yaw: f64) -> f64 {
        if !yaw.is_finite() {
            return yaw;
        }
        let out = match self.last {
            None => yaw,
            Some((last_in, last_out)) => last_out + wrap_angle(yaw - last_in),
        };
        self.last = Some((yaw, out));
        out
    }

    /// Forgets the history (the next output equals its input).
    pub fn reset(&mut self) {
        self.last = None;
    }
}

/// `geometry_msgs/msg/Twist`: linear (m/s) and angular (rad/s) velocity.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Twist {
    /// Linear velocity, m/s (x forward).
    pub linear: Vector3,
    /// Angular velocity, rad/s (z counter-clockwise).
    pub angular: Vector3,
}

impl Twist {
    /// A planar command: `v` forward (m/s), `omega` about z (rad/s).
    pub fn planar(v: f64, omega: f64) -> Twist {
        Twist {
            linear: Vector3 {
                x: v,
                ..Vector3::default()
            },
            angular: Vector3 {
                z: omega,
                ..Vector3::default()
            },
        }
    }

    fn non_finite(&self, linear: &'static str, angular: &'static str) -> Option<&'static str> {
        if !self.linear.is_finite() {
            Some(linear)
        } else if !self.angular.is_finite() {
            Some(angular)
        } else {
            None
        }
    }

    fn write(&self, w: &mut CdrWriter<'_>) {
        self.linear.write(w);
        self.angular.write(w);
    }

    fn read(
        r: &mut CdrReader<'_>,
        linear: &'static str,
        angular: &'static str,
    ) -> Result<Twist, CdrError> {
        Ok(Twist {
            linear: Vector3::read(r, linear)?,
            angular: Vector3::read(r, angular)?,
        })
    }
}

impl RosMessage for Twist {
    const TYPE: MessageType = TWIST;

    fn write_cdr(&self, w: &mut CdrWriter<'_>) {
        self.write(w);
    }

    fn read_cdr(r: &mut CdrReader<'_>) -> Result<Twist, CdrError> {
        Twist::read(r, "linear", "angular")
    }

    fn first_non_finite(&self) -> Option<&'static str> {
        self.non_finite("linear", "angular")
    }
}

/// `geometry_msgs/msg/TwistStamped`, what `diff_drive_controller` takes on
/// `cmd_vel` since Jazzy.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TwistStamped {
    /// Stamp and frame (`base_link`).
    pub header: Header,
    /// The command.
    pub twist: Twist,
}

impl TwistStamped {
    /// A planar command stamped `stamp` in `frame_id`.
    pub fn planar(v: f64, omega: f64, stamp: Time, frame_id: &str) -> TwistStamped {
        TwistStamped {
            header: Header {
                stamp,
                frame_id: frame_id.to_owned(),
            },
            twist: Twist::planar(v, omega),
        }
    }
}

impl RosMessage for TwistStamped {
    const TYPE: MessageType = TWIST_STAMPED;

    fn write_cdr(&self, w: &mut CdrWriter<'_>) {
        self.header.write(w);
        self.twist.write(w);
    }

    fn read_cdr(r: &mut CdrReader<'_>) -> Result<TwistStamped, CdrError> {
        Ok(TwistStamped {
            header: Header::read(r)?,
            twist: Twist::read(r, "twist.linear", "twist.angular")?,
        })
    }

    fn first_non_finite(&self) -> Option<&'static str> {
        self.twist.non_finite("twist.linear", "twist.angular")
    }
}

/// `geometry_msgs/msg/Pose`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// Position, m (a `Point`).
    pub position: Vector3,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/PoseWithCovariance`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseWithCovariance {
    /// The pose.
    pub pose: Pose,
    /// Row-major 6×6 covariance of (x, y, z, roll, pitch, yaw).
    pub covariance: [f64; 36],
}

/// `geometry_msgs/msg/TwistWithCovariance`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwistWithCovariance {
    /// The twist.
    pub twist: Twist,
    /// Row-major 6×6 covariance of (vx, vy, vz, ωx, ωy, ωz).
    pub covariance: [f64; 36],
}

impl Default for PoseWithCovariance {
    fn default() -> PoseWithCovariance {
        PoseWithCovariance {
            pose: Pose::default(),
            covariance: [0.0; 36],
        }
    }
}

impl Default for TwistWithCovariance {
    fn default() -> TwistWithCovariance {
        TwistWithCovariance {
            twist: Twist::default(),
            covariance: [0.0; 36],
        }
    }
}

/// `nav_msgs/msg/Odometry`: pose in `header.frame_id`, twist in `child_frame_id`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Odometry {
    /// Stamp and pose frame (`odom`).
    pub header: Header,
    /// Twist frame (`base_link`).
    pub child_frame_id: String,
    /// Pose and covariance.
    pub pose: PoseWithCovariance,
    /// Twist and covariance.
    pub twist: TwistWithCovariance,
}

impl Odometry {
    /// A planar odometry: at (`x`, `y`) heading `yaw` in `frame_id`, moving
    /// at `v` forward and `omega` about z in `child_frame_id`; zero covariances.
    #[allow(clippy::too_many_arguments)]
    pub fn planar(
        x: f64,
        y: f64,
        yaw: f64,
        v: f64,
        omega: f64,
        stamp: Time,
        frame_id: &str,
        child_frame_id: &str,
    ) -> Odometry {
        Odometry {
            header: Header {
                stamp,
                frame_id: frame_id.to_owned(),
            },
            child_frame_id: child_frame_id.to_owned(),
            pose: PoseWithCovariance {
                pose: Pose {
                    position: Vector3 { x, y, z: 0.0 },
                    orientation: Quaternion::from_yaw(yaw),
                },
                covariance: [0.0; 36],
            },
            twist: TwistWithCovariance {
                twist: Twist::planar(v, omega),
                covariance: [0.0; 36],
            },
        }
    }

    /// Yaw of the pose (rad, `[-π, π]`); feed it to a [`YawUnwrapper`].
    pub fn yaw(&self) -> f64 {
        self.pose.pose.orientation.yaw()
    }
}

fn write_covariance(w: &mut CdrWriter<'_>, c: &[f64; 36]) {
    for &v in c {
        w.write_f64(v);
    }
}

fn read_covariance(r: &mut CdrReader<'_>, field: &'static str) -> Result<[f64; 36], CdrError> {
    let mut c = [0.0; 36];
    for v in &mut c {
        *v = r.read_f64(field)?;
    }
    Ok(c)
}

impl RosMessage for Odometry {
    const TYPE: MessageType = ODOMETRY;

    fn write_cdr(&self, w: &mut CdrWriter<'_>) {
        self.header.write(w);
        w.write_string(&self.child_frame_id);
        self.pose.pose.position.write(w);
        self.pose.pose.orientation.write(w);
        write_covariance(w, &self.pose.covariance);
        self.twist.twist.write(w);
        write_covariance(w, &self.twist.covariance);
    }

    fn read_cdr(r: &mut CdrReader<'_>) -> Result<Odometry, CdrError> {
        let header = Header::read(r)?;
        let child_frame_id = r.read_string("child_frame_id")?.to_owned();
        let position = Vector3::read(r, "pose.pose.position")?;
        let orientation = Quaternion::read(r)?;
        let pose_cov = read_covariance(r, "pose.covariance")?;
        let twist = Twist::read(r, "twist.twist.linear", "twist.twist.angular")?;
        let twist_cov = read_covariance(r, "twist.covariance")?;
        Ok(Odometry {
            header,
            child_frame_id,
            pose: PoseWithCovariance {
                pose: Pose {
                    position,
                    orientation,
                },
                covariance: pose_cov,
            },
            twist: TwistWithCovariance {
                twist,
                covariance: twist_cov,
            },
        })
    }

    fn first_non_finite(&self) -> Option<&'static str> {
        if !self.pose.pose.position.is_finite() {
            Some("pose.pose.position")
        } else if !self.pose.pose.orientation.is_finite() {
            Some("pose.pose.orientation")
        } else if !self.pose.covariance.iter().all(|v| v.is_finite()) {
            Some("pose.covariance")
        } else if let Some(f) = self
            .twist
            .twist
            .non_finite("twist.twist.linear", "twist.twist.angular")
        {
            Some(f)
        } else if !self.twist.covariance.iter().all(|v| v.is_finite()) {
            Some("twist.covariance")
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `rclpy.serialization.serialize_message` of a TwistStamped with
    /// `header.frame_id = "base_link"` and `twist.linear.x = 0.5` (ROS 2
    /// Jazzy wheels). Bytes 18..20 are Fast-CDR's uninitialised padding: here
    /// `73 ba`, whatever was in memory.
    const RCLPY_TWIST_STAMPED: &str = "0001000000000000000000000a000000626173655f6c696e6b0073ba\
        000000000000e03f\
        0000000000000000000000000000000000000000\
        0000000000000000000000000000000000000000";

    fn hex(s: &str) -> Vec<u8> {
        (0..s.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&s[i..i + 2], 16).expect("hex"))
            .collect()
    }

    #[test]
    fn an_rclpy_twist_stamped_with_garbage_padding_decodes() {
        let bytes = hex(RCLPY_TWIST_STAMPED);
        let msg = TwistStamped::from_cdr_finite(&bytes).expect("decodes");
        assert_eq!(
            msg,
            TwistStamped::planar(0.5, 0.0, Time::default(), "base_link")
        );
        // Ours differs only in the padding.
        let ours = msg.to_cdr();
        assert_eq!(ours.len(), bytes.len());
        let differing: Vec<usize> = (0..ours.len()).filter(|&i| ours[i] != bytes[i]).collect();
        assert_eq!(differing, vec![26, 27]);
    }

    #[test]
    fn dds_names_are_mangled_as_rmw_zenoh_does() {
        assert_eq!(
            TWIST_STAMPED.dds_name(),
            "geometry_msgs::msg::dds_::TwistStamped_"
        );
        assert_eq!(ODOMETRY.dds_name(), "nav_msgs::msg::dds_::Odometry_");
    }

    #[test]
    fn yaw_of_from_yaw_is_the_wrapped_angle() {
        for k in -20..=20 {
            let a = f64::from(k) * 0.37;
            let q = Quaternion::from_yaw(a);
            assert!((wrap_angle(q.yaw() - a)).abs() < 1e-12, "{a}");
            // Scaled (not normalised) quaternions give the same yaw.
            let s = Quaternion {
                x: 3.0 * q.x,
                y: 3.0 * q.y,
                z: 3.0 * q.z,
                w: 3.0 * q.w,
            };
            assert!((s.yaw() - q.yaw()).abs() < 1e-12);
        }
    }

    #[test]
    fn the_unwrapper_counts_turns() {
        let mut u = YawUnwrapper::new();
        // Turning counter-clockwise 0.3 rad a step for three turns.
        for k in 0..63 {
            let heading = f64::from(k) * 0.3;
            let out = u.unwrap(wrap_angle(heading));
            assert!((out - heading).abs() < 1e-9, "{k}: {out} vs {heading}");
        }
        assert!(u.unwrap(f64::NAN).is_nan());
        assert!((u.unwrap(wrap_angle(62.0 * 0.3 - 0.1)) - (62.0 * 0.3 - 0.1)).abs() < 1e-9);
    }

    #[test]
    fn time_from_nanos_round_trips_and_saturates() {
        for ns in [0i64, 1, 999_999_999, 1_000_000_000, -1, -1_500_000_000] {
            let t = Time::from_nanos(ns);
            assert!(t.nanosec < 1_000_000_000);
            assert_eq!(t.to_nanos(), ns);
        }
        assert_eq!(Time::from_nanos(i64::MAX).sec, i32::MAX);
        assert_eq!(Time::from_nanos(i64::MIN).sec, i32::MIN);
    }
}
