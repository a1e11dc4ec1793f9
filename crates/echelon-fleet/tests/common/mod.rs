//! Shared by the ROS 2 test binaries: message values as the Python helpers
//! (`scripts/ros2/*.py`) write them, every float64 as its IEEE-754 bit
//! pattern so that comparisons are exact (NaN, -0.0, infinities).

#![allow(dead_code)]

use echelon_ros2::msgs::{Header, Odometry, Point, Quaternion, Twist, TwistStamped, Vector3};
use serde_json::{Value, json};

pub(crate) fn f(x: f64) -> Value {
    Value::from(x.to_bits())
}

pub(crate) fn vec3(v: &Vector3) -> Value {
    json!({"x": f(v.x), "y": f(v.y), "z": f(v.z)})
}

pub(crate) fn point(&Point { x, y, z }: &Point) -> Value {
    vec3(&Vector3 { x, y, z })
}

pub(crate) fn quat(q: &Quaternion) -> Value {
    json!({"x": f(q.x), "y": f(q.y), "z": f(q.z), "w": f(q.w)})
}

pub(crate) fn header(h: &Header) -> Value {
    json!({"stamp": {"sec": h.stamp.sec, "nanosec": h.stamp.nanosec}, "frame_id": h.frame_id})
}

pub(crate) fn twist(t: &Twist) -> Value {
    json!({"linear": vec3(&t.linear), "angular": vec3(&t.angular)})
}

pub(crate) fn twist_stamped(t: &TwistStamped) -> Value {
    json!({"header": header(&t.header), "twist": twist(&t.twist)})
}

pub(crate) fn covariance(c: &[f64; 36]) -> Value {
    Value::from(c.iter().map(|&x| f(x)).collect::<Vec<_>>())
}

pub(crate) fn odometry(o: &Odometry) -> Value {
    json!({
        "header": header(&o.header),
        "child_frame_id": o.child_frame_id,
        "pose": {
            "pose": {"position": point(&o.pose.pose.position), "orientation": quat(&o.pose.pose.orientation)},
            "covariance": covariance(&o.pose.covariance),
        },
        "twist": {"twist": twist(&o.twist.twist), "covariance": covariance(&o.twist.covariance)},
    })
}
