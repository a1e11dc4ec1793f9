//! The Create 3's hazard messages and the e-stop's `Bool`, which no ROS 2
//! wheel ships (irobot_create_msgs) or which echelon reads from a base
//! (std_msgs/Bool), against an independent implementation: `rosbags`
//! builds its CDR codec and its RIHS01 type hash from the `.msg` text alone
//! (`scripts/ros2/rosbags_codec.py`).
//!
//! - echelon's encodings decode in rosbags to the same values, and
//!   rosbags' encodings are byte for byte echelon's, over random vectors
//!   (any number of detections, any frame ids, any known types);
//! - the type hashes echelon generates equal rosbags';
//! - every proper prefix of an encoding is refused, never a panic.
//!
//! They need `python3` with `rosbags` (`scripts/test` installs
//! `scripts/requirements-test.txt`).

use echelon_fleet::ros2::hazard::{BaseSafety, Hazard};
use echelon_ros2::msgs::{
    BOOL, Bool, HAZARD_DETECTION, HAZARD_DETECTION_VECTOR, HazardDetection, HazardDetectionVector,
    Header, RosMessage, Time,
};
use echelon_ros2::names::KeyScheme;
use proptest::prelude::*;
use serde_json::{Value, json};

mod common;
#[path = "common/python.rs"]
mod python;
use python::Helpers;

const INSTALL_HINT: &str = "the hazard codec tests need python3 with `rosbags` (pinned in \
    scripts/requirements-test.txt; `scripts/test` installs it)";

fn msg_text(ty: &str) -> String {
    let path = format!(
        "{}/../echelon-ros2/msg/irobot_create_msgs/{ty}.msg",
        env!("CARGO_MANIFEST_DIR")
    );
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

fn rosbags(request: Value) -> Value {
    let mut req = request;
    req["msgs"] = json!({
        "irobot_create_msgs/msg/HazardDetection": msg_text("HazardDetection"),
        "irobot_create_msgs/msg/HazardDetectionVector": msg_text("HazardDetectionVector"),
    });
    Helpers::new(INSTALL_HINT)
        .run("rosbags_codec.py", &[], Some(&req))
        .unwrap_or_else(|e| panic!("{e}"))
}

fn header_json(h: &Header) -> Value {
    json!({"stamp": {"sec": h.stamp.sec, "nanosec": h.stamp.nanosec}, "frame_id": h.frame_id})
}

fn vector_json(v: &HazardDetectionVector) -> Value {
    json!({
        "header": header_json(&v.header),
        "detections": v.detections.iter().map(|d| json!({"header": header_json(&d.header), "type": d.r#type})).collect::<Vec<_>>(),
    })
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

fn unhex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap_or_else(|e| panic!("{e}")))
        .collect()
}

#[test]
fn type_hashes_are_rosbags() {
    let r =
        rosbags(json!({"hash": [HAZARD_DETECTION_VECTOR.name, HAZARD_DETECTION.name, BOOL.name]}));
    for ty in [HAZARD_DETECTION_VECTOR, HAZARD_DETECTION, BOOL] {
        assert_eq!(r["hashes"][ty.name], ty.hash, "{}", ty.name);
    }
}

fn header() -> impl Strategy<Value = Header> {
    (any::<i32>(), 0u32..1_000_000_000, "[a-z_]{0,20}").prop_map(|(sec, nanosec, frame_id)| {
        Header {
            stamp: Time { sec, nanosec },
            frame_id,
        }
    })
}

fn vector() -> impl Strategy<Value = HazardDetectionVector> {
    (
        header(),
        proptest::collection::vec((header(), 0u8..=5), 0..6),
    )
        .prop_map(|(header, d)| HazardDetectionVector {
            header,
            detections: d
                .into_iter()
                .map(|(header, ty)| HazardDetection { header, r#type: ty })
                .collect(),
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 16, ..ProptestConfig::default() })]

    /// Both ways, over random vectors and e-stops in one rosbags call per case.
    #[test]
    fn encodings_agree_both_ways(vs in proptest::collection::vec(vector(), 1..5), on in any::<bool>()) {
        let encode: Vec<Value> = vs.iter().map(|v| json!({"type": HAZARD_DETECTION_VECTOR.name, "value": vector_json(v)}))
            .chain(std::iter::once(json!({"type": BOOL.name, "value": {"data": on}})))
            .collect();
        let decode: Vec<Value> = vs.iter().map(|v| json!({"type": HAZARD_DETECTION_VECTOR.name, "hex": hex(&v.to_cdr())})).collect();
        let r = rosbags(json!({"encode": encode, "decode": decode}));
        for (i, v) in vs.iter().enumerate() {
            let theirs = unhex(r["encoded"][i].as_str().unwrap_or_default());
            // Same bytes (echelon writes zero padding, as rosbags does).
            prop_assert_eq!(hex(&theirs), hex(&v.to_cdr()));
            prop_assert_eq!(HazardDetectionVector::from_cdr(&theirs), Ok(v.clone()));
            prop_assert_eq!(&r["decoded"][i], &vector_json(v));
            for n in 0..theirs.len() {
                prop_assert!(HazardDetectionVector::from_cdr(&theirs[..n]).is_err(), "prefix {n}");
            }
        }
        let estop = unhex(r["encoded"][vs.len()].as_str().unwrap_or_default());
        prop_assert_eq!(Bool::from_cdr(&estop), Ok(Bool { data: on }));
        prop_assert_eq!(hex(&estop), hex(&Bool { data: on }.to_cdr()));
        // A base's safety words read from rosbags' bytes.
        let mut b = BaseSafety::new(KeyScheme::Bridge);
        let last = unhex(r["encoded"][vs.len() - 1].as_str().unwrap_or_default());
        let all = b.on_hazards("bot1/hazard_detection", &last, 0.0).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let expected: Vec<Hazard> = Hazard::ALL.into_iter().filter(|h| vs[vs.len() - 1].detections.iter().any(|d| Hazard::of_create3(d.r#type) == Some(*h))).collect();
        prop_assert_eq!(all.iter().collect::<Vec<_>>(), expected);
    }
}
