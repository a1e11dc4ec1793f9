#![allow(clippy::unwrap_used)]

use foxglove::Decode;
use proptest::prelude::*;

use super::*;

fn spec(leaders: Vec<Leader>, safety_radius: Option<f64>) -> SceneSpec {
    SceneSpec {
        l: vec![0.1; leaders.len()],
        leaders,
        safety_radius,
        obstacles: vec![[1.0, 2.0, 0.5]],
        path: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]],
    }
}

/// `R(θ) a` (world to body frame).
fn to_body(theta: f64, a: [f64; 2]) -> [f64; 2] {
    let (s, c) = theta.sin_cos();
    [c * a[0] + s * a[1], -s * a[0] + c * a[1]]
}

proptest! {
    /// With `e = R(θ)(p − p_d) + L` (eq. 7), the slot is `p_d − R(θ)ᵀ L`
    /// wherever the robot stands.
    #[test]
    fn the_slot_is_where_eq_7_gives_zero_error(
        p in prop::array::uniform2(-50.0..50.0f64),
        pd in prop::array::uniform2(-50.0..50.0f64),
        theta in -10.0..10.0f64,
        l in prop::array::uniform2(-2.0..2.0f64),
    ) {
        let d = to_body(theta, [p[0] - pd[0], p[1] - pd[1]]);
        let e = [d[0] + l[0], d[1] + l[1]];
        let at = ScenePose { t: 0.0, p, theta, e, leader: pd };
        let slot = at.slot();
        let (s, c) = theta.sin_cos();
        let want = [pd[0] - (c * l[0] - s * l[1]), pd[1] - (s * l[0] + c * l[1])];
        prop_assert!((slot[0] - want[0]).abs() < 1e-9 && (slot[1] - want[1]).abs() < 1e-9,
            "{slot:?} vs {want:?}");
    }

    /// What [`Scene::set`] puts in robot k's messages comes back from
    /// their protobuf bytes: the transform's translation and yaw, the
    /// body at p, the slot, the link from p to p_d; other robots untouched.
    #[test]
    fn a_robots_messages_round_trip_through_protobuf(
        p in prop::array::uniform2(-50.0..50.0f64),
        pd in prop::array::uniform2(-50.0..50.0f64),
        e in prop::array::uniform2(-1.0..1.0f64),
        theta in -3.1..3.1f64,
        t in 0.0..1e4f64,
        k in 1u32..=3,
    ) {
        let mut scene = Scene::new(&spec(
            vec![Leader::Reference, Leader::Agent(0), Leader::Agent(1)],
            Some(0.3),
        ));
        let at = ScenePose { t, p, theta, e, leader: pd };
        scene.set(k, &at).unwrap();
        let (tf, update) = scene.robot(k).unwrap();
        let mut buf = Vec::new();
        tf.encode(&mut buf).unwrap();
        let tf = FrameTransforms::decode(&buf[..]).unwrap();
        let tr = &tf.transforms[0];
        prop_assert_eq!(&tr.parent_frame_id, WORLD_FRAME);
        prop_assert_eq!(&tr.child_frame_id, &base_link(k));
        let v = tr.translation.unwrap();
        prop_assert_eq!((v.x, v.y, v.z), (p[0], p[1], 0.0));
        let q = tr.rotation.unwrap();
        let yaw = 2.0 * q.z.atan2(q.w);
        prop_assert!((yaw - theta).abs() < 1e-12, "{} vs {}", yaw, theta);
        prop_assert_eq!(tr.timestamp.unwrap(), timestamp(t));

        buf.clear();
        update.encode(&mut buf).unwrap();
        let update = SceneUpdate::decode(&buf[..]).unwrap();
        let ids: Vec<&str> = update.entities.iter().map(|e| e.id.as_str()).collect();
        let want = [format!("robot{k}"), format!("robot{k}/slot"),
            format!("robot{k}/link"), format!("robot{k}/safety")];
        prop_assert_eq!(ids, want.iter().map(String::as_str).collect::<Vec<_>>());
        let position = |pose: &Option<Pose>| {
            let v = pose.unwrap().position.unwrap();
            [v.x, v.y]
        };
        prop_assert_eq!(position(&update.entities[BODY].cylinders[0].pose), p);
        prop_assert_eq!(position(&update.entities[SLOT].spheres[0].pose), at.slot());
        prop_assert_eq!(position(&update.entities[SAFETY].cylinders[0].pose), p);
        let link = &update.entities[LINK].lines[0].points;
        prop_assert_eq!([link[0].x, link[0].y, link[1].x, link[1].y], [p[0], p[1], pd[0], pd[1]]);
        for other in (1..=3).filter(|&j| j != k) {
            let tr = &scene.robot(other).unwrap().0.transforms[0];
            prop_assert_eq!(tr.translation.unwrap(), Vector3::default());
        }
    }
}

/// The schemas are Foxglove's well-known ones, as the foxglove crate
/// gives them, and the fixed scene holds the path and each obstacle.
#[test]
fn channels_carry_foxglove_schemas_and_the_fixed_scene() {
    let mut log = McapLog::new(std::io::Cursor::new(Vec::new())).unwrap();
    let mut channels = SceneChannels::register(&mut log).unwrap();
    let mut scene = Scene::new(&spec(vec![Leader::Reference], None));
    channels.fixed(&mut log, &mut scene, 0.5, 7).unwrap();
    scene
        .set(
            1,
            &ScenePose {
                t: 0.5,
                p: [1.0, 2.0],
                theta: 0.3,
                e: [0.0; 2],
                leader: [0.0; 2],
            },
        )
        .unwrap();
    channels.robot(&mut log, &scene, 1, 8, 9).unwrap();
    assert!(
        scene
            .set(
                2,
                &ScenePose {
                    t: 0.5,
                    p: [0.0; 2],
                    theta: 0.0,
                    e: [0.0; 2],
                    leader: [0.0; 2]
                }
            )
            .is_none()
    );
    let bytes = log.finish().unwrap().into_inner();
    let mut topics = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let schema = m.channel.schema.as_ref().unwrap();
        assert_eq!(schema.encoding, "protobuf");
        assert_eq!(m.channel.message_encoding, "protobuf");
        let name = if m.channel.topic == TF_TOPIC {
            "foxglove.FrameTransforms"
        } else {
            "foxglove.SceneUpdate"
        };
        assert_eq!(schema.name, name);
        assert!(!schema.data.is_empty());
        if m.channel.topic == SCENE_STATIC_TOPIC {
            let fixed = SceneUpdate::decode(&m.data[..]).unwrap();
            let ids: Vec<&str> = fixed.entities.iter().map(|e| e.id.as_str()).collect();
            assert_eq!(ids, ["reference", "obstacle/1"]);
            assert_eq!(fixed.entities[0].lines[0].points.len(), 3);
            let o = &fixed.entities[1].cylinders[0];
            assert_eq!(o.size.unwrap().x, 1.0);
            assert_eq!((m.log_time, m.publish_time), (7, 500_000_000));
        } else {
            assert_eq!((m.log_time, m.publish_time), (8, 9));
        }
        if m.channel.topic == SCENE_TOPIC {
            // Without a safety radius, no safety circle.
            let update = SceneUpdate::decode(&m.data[..]).unwrap();
            assert_eq!(update.entities.len(), 3);
        }
        topics.push(m.channel.topic.clone());
    }
    assert_eq!(topics, [SCENE_STATIC_TOPIC, TF_TOPIC, SCENE_TOPIC]);
}
