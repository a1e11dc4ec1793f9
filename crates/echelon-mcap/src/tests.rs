#![allow(clippy::unwrap_used)]

use std::collections::BTreeSet;
use std::io::Cursor;

use echelon::sample::AgentSample;
use echelon::scenario::{Overrides, Scenario};
use echelon::sim::Every;
use serde_json::Value;

use super::*;

/// The JSON type names `value` may carry (a whole number is also a number).
fn types_of(value: &Value) -> Vec<&'static str> {
    match value {
        Value::Null => vec!["null"],
        Value::Bool(_) => vec!["boolean"],
        Value::Number(n) if n.is_f64() => vec!["number"],
        Value::Number(_) => vec!["integer", "number"],
        Value::String(_) => vec!["string"],
        Value::Array(_) => vec!["array"],
        Value::Object(_) => vec!["object"],
    }
}

/// Checks `value` against the subset of JSON Schema the derived schemas
/// use (`type`, `properties`, `required`, `minimum`); names where it fails.
fn conforms(value: &Value, schema: &Value, at: &str) -> Result<(), String> {
    let allowed: Vec<&str> = match &schema["type"] {
        Value::String(t) => vec![t.as_str()],
        Value::Array(ts) => ts.iter().filter_map(Value::as_str).collect(),
        other => return Err(format!("{at}: schema without a type: {other}")),
    };
    if !types_of(value).iter().any(|t| allowed.contains(t)) {
        return Err(format!("{at}: {value} is not of type {allowed:?}"));
    }
    if let (Some(min), Some(v)) = (schema["minimum"].as_f64(), value.as_f64())
        && v < min
    {
        return Err(format!("{at}: {v} < minimum {min}"));
    }
    if let Value::Object(fields) = value {
        let properties = schema["properties"]
            .as_object()
            .ok_or_else(|| format!("{at}: an object schema without properties"))?;
        for (k, v) in fields {
            let sub = properties
                .get(k)
                .ok_or_else(|| format!("{at}: field `{k}` is not in the schema"))?;
            conforms(v, sub, &format!("{at}.{k}"))?;
        }
        for r in schema["required"].as_array().into_iter().flatten() {
            let r = r.as_str().unwrap();
            if !fields.contains_key(r) {
                return Err(format!("{at}: required field `{r}` missing"));
            }
        }
    }
    Ok(())
}

/// The paper's circle experiment, `duration` s long.
fn circle(duration: f64) -> echelon::Run {
    scenario("experiment-circle", duration)
}

/// The built-in scenario `name`, `duration` s long.
fn scenario(name: &str, duration: f64) -> echelon::Run {
    Scenario::builtin(name)
        .unwrap()
        .build(&Overrides {
            duration: Some(duration),
            ..Overrides::default()
        })
        .unwrap()
}

fn keys(v: &Value) -> BTreeSet<String> {
    v.as_object().unwrap().keys().cloned().collect()
}

fn schema(s: &JsonSchema) -> Value {
    serde_json::from_str(&s.schema).unwrap()
}

/// A fleet record of a velocity base: every field there is.
fn fleet_state() -> AgentStateRecord {
    let mut record = AgentStateRecord {
        seq: Some(7),
        link: Some("tracking"),
        leader: Some(LeaderRecord {
            x: 1.0,
            y: 2.0,
            vx: 0.5,
            vy: -0.5,
            ax: 0.0,
            ay: 0.25,
        }),
        odometry: Some(OdometryRecord {
            raw: [0.5, -0.25, 6.5],
            age: 0.01,
            fix_age: Some(0.05),
        }),
        sigma: Some(0.02),
        ..AgentStateRecord::new(AgentSample::new(
            1.5,
            2,
            &echelon::State {
                x: 1.0,
                y: -1.0,
                theta: 4.0,
                v: 0.3,
                omega: -0.1,
            },
            &echelon::sim::AgentOutput::default(),
        ))
    };
    record.sample.velocity = Some(echelon::sample::VelocitySample::default());
    record
}

#[test]
fn schemas_have_exactly_the_serialised_fields() {
    let agent = schema(&AGENT_STATE);
    let full = serde_json::to_value(fleet_state()).unwrap();
    assert_eq!(keys(&agent["properties"]), keys(&full));
    assert_eq!(
        keys(&agent["properties"]["leader"]["properties"]),
        keys(&full["leader"])
    );
    // The fields a simulated run always writes are the required ones.
    let sim = serde_json::to_value(AgentStateRecord {
        seq: None,
        link: None,
        leader: None,
        odometry: None,
        sigma: None,
        sample: AgentSample {
            velocity: None,
            ..fleet_state().sample
        },
        ..fleet_state()
    })
    .unwrap();
    let required: BTreeSet<String> = agent["required"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r.as_str().unwrap().to_owned())
        .collect();
    assert_eq!(required, keys(&sim));
    for record in [&full, &sim] {
        conforms(record, &agent, "AgentState").unwrap();
    }
    assert_eq!(agent["title"], "echelon.AgentState");

    let reference = schema(&REFERENCE);
    let fleet = ReferenceRecord {
        seq: Some(3),
        ..ReferenceRecord::at(circle(0.5).plan.reference(), 0.5)
    };
    let full = serde_json::to_value(fleet).unwrap();
    assert_eq!(keys(&reference["properties"]), keys(&full));
    conforms(&full, &reference, "Reference").unwrap();
    assert_eq!(reference["title"], "echelon.Reference");
}

#[test]
fn the_checker_refuses_what_the_schema_does_not_describe() {
    let agent = schema(&AGENT_STATE);
    let mut record = serde_json::to_value(fleet_state()).unwrap();
    record["extra"] = Value::from(1.0);
    assert!(conforms(&record, &agent, "a").is_err());
    let mut record = serde_json::to_value(fleet_state()).unwrap();
    record["agent"] = Value::from("one");
    assert!(conforms(&record, &agent, "a").is_err());
    let mut record = serde_json::to_value(fleet_state()).unwrap();
    record.as_object_mut().unwrap().remove("t");
    assert!(conforms(&record, &agent, "a").is_err());
}

/// A simulated run through the observer, torque-driven or on velocity
/// bases: every message conforms to its channel's schema, one message
/// per channel per logged frame, and the file is finished (readable
/// summary).
#[test]
fn every_message_of_a_run_conforms_to_its_channel_schema() {
    for name in ["experiment-circle", "experiment-circle-velocity"] {
        a_run_conforms(name);
    }
}

fn a_run_conforms(name: &str) {
    let run = scenario(name, 0.5);
    let velocity = run.plan.agents()[0].velocity_robot().is_some();
    let every = 7;
    let mut mcap = Every::new(every, McapObserver::new(Cursor::new(Vec::new())).unwrap());
    run.simulation().run(&mut mcap).unwrap();
    let bytes = mcap.into_inner().into_inner().unwrap().into_inner();
    let steps = run.plan.steps();
    let frames = steps / every + 1 + u64::from(!steps.is_multiple_of(every));
    let mut counts: BTreeMap<String, u64> = BTreeMap::new();
    let mut scene_counts: BTreeMap<String, u64> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let schema = m.channel.schema.as_ref().unwrap();
        if schema.encoding != "jsonschema" {
            // The 3D channels: Foxglove's schemas, checked in scene's tests.
            assert_eq!(
                (
                    schema.encoding.as_str(),
                    m.channel.message_encoding.as_str()
                ),
                ("protobuf", "protobuf")
            );
            *scene_counts.entry(m.channel.topic.clone()).or_default() += 1;
            continue;
        }
        let schema: Value = serde_json::from_slice(&schema.data).unwrap();
        let record: Value = serde_json::from_slice(&m.data).unwrap();
        conforms(&record, &schema, &m.channel.topic).unwrap();
        if m.channel.topic != REFERENCE_TOPIC {
            assert_eq!(record.get("v_cmd").is_some(), velocity, "{record}");
        }
        *counts.entry(m.channel.topic.clone()).or_default() += 1;
    }
    let agents = run.plan.agents().len();
    assert_eq!(counts.len(), agents + 1);
    assert!(counts.values().all(|&n| n == frames), "{counts:?}");
    let agents = agents as u64;
    assert_eq!(
        scene_counts,
        BTreeMap::from([
            (scene::TF_TOPIC.to_owned(), frames * agents),
            (scene::SCENE_TOPIC.to_owned(), frames * agents),
            (scene::SCENE_STATIC_TOPIC.to_owned(), 1),
        ])
    );
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert_eq!(
        summary.stats.unwrap().message_count,
        frames * (agents + 1) + 2 * frames * agents + 1
    );
}

/// A ROS 2 channel as rosbag2 writes it, next to a JSON one: schema
/// `ros2msg` with the definition, channel `cdr` with its metadata, the
/// bytes as given; one schema for two topics of a type; a topic cannot
/// change schema.
#[test]
fn ros2_channels_are_written_as_rosbag2_writes_them() {
    const TWIST: Ros2Schema = Ros2Schema {
        name: "geometry_msgs/msg/Twist",
        definition: "Vector3  linear\nVector3  angular\n\n\
                ================================================================================\n\
                MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n",
        type_hash: "RIHS01_00",
    };
    let mut log = McapLog::new(Cursor::new(Vec::new())).unwrap();
    let json = log.channel(REFERENCE_TOPIC, &REFERENCE).unwrap();
    let a = log
        .ros2_channel("/a/cmd_vel", &TWIST, "- depth: 10")
        .unwrap();
    let b = log.ros2_channel("/b/cmd_vel", &TWIST, "[]").unwrap();
    assert_eq!(log.ros2_channel("/a/cmd_vel", &TWIST, "x").unwrap(), a);
    let clash = log.ros2_channel(REFERENCE_TOPIC, &TWIST, "[]").unwrap_err();
    assert!(
        matches!(&clash, McapLogError::TopicSchema { registered, .. } if registered == "echelon.Reference"),
        "{clash}"
    );
    assert!(log.channel("/a/cmd_vel", &REFERENCE).is_err());
    let payload = [0u8, 1, 0, 0, 0xaa, 0xbb];
    log.write(a, 0, 10, 5, &payload).unwrap();
    log.write(b, 0, 11, 6, &payload[..4]).unwrap();
    log.write_json(json, 0, 12, 12, &serde_json::json!({}))
        .unwrap();
    let bytes = log.finish().unwrap().into_inner();

    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert_eq!(summary.schemas.len(), 2);
    let mut seen = 0;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let schema = m.channel.schema.as_ref().unwrap();
        if m.channel.topic == REFERENCE_TOPIC {
            assert_eq!(
                (
                    m.channel.message_encoding.as_str(),
                    schema.encoding.as_str()
                ),
                ("json", "jsonschema")
            );
            assert!(m.channel.metadata.is_empty());
            continue;
        }
        seen += 1;
        assert_eq!(m.channel.message_encoding, CDR);
        assert_eq!(schema.encoding, ROS2MSG);
        assert_eq!(schema.name, TWIST.name);
        assert_eq!(&schema.data[..], TWIST.definition.as_bytes());
        assert_eq!(m.channel.metadata["topic_type_hash"], "RIHS01_00");
        let (qos, len, times) = if m.channel.topic == "/a/cmd_vel" {
            ("- depth: 10", 6, (10, 5))
        } else {
            ("[]", 4, (11, 6))
        };
        assert_eq!(m.channel.metadata["offered_qos_profiles"], qos);
        assert_eq!(&m.data[..], &payload[..len]);
        assert_eq!((m.log_time, m.publish_time), times);
    }
    assert_eq!(seen, 2);
}
