use super::*;
use proptest::prelude::*;

fn finite() -> impl Strategy<Value = f64> {
    -1e6..1e6f64
}

/// No block, a block without a fix, a block with one.
fn odometry() -> impl Strategy<Value = Option<OdometryState>> {
    (
        0..3u8,
        proptest::array::uniform3(finite()),
        0.0..1e3f64,
        0.0..1e3f64,
    )
        .prop_map(|(kind, raw, age, fix_age)| {
            (kind > 0).then_some(OdometryState {
                raw,
                age,
                fix_age: (kind == 2).then_some(fix_age),
            })
        })
}

/// `N` finite numbers.
fn finites<const N: usize>() -> impl Strategy<Value = [f64; N]> {
    proptest::array::uniform(finite())
}

/// A robot's state `[x, y, θ, v, ω]`.
fn state() -> impl Strategy<Value = State> {
    finites::<5>().prop_map(|[x, y, theta, v, omega]| State {
        x,
        y,
        theta,
        v,
        omega,
    })
}

/// A leader's motion `p, ṗ, p̈`.
fn motion() -> impl Strategy<Value = LeaderMotion> {
    (finites::<2>(), finites::<2>(), finites::<2>()).prop_map(|(p, dp, ddp)| LeaderMotion {
        p,
        dp,
        ddp,
    })
}

/// No velocity block (torque-driven), or a velocity base's, its limits
/// cutting the command or not.
fn velocity() -> impl Strategy<Value = Option<VelocitySample>> {
    (0..3u8, finites::<4>()).prop_map(|(drive, [v_cmd, omega_cmd, v_applied, omega_applied])| {
        (drive > 0).then_some(VelocitySample {
            v_cmd,
            omega_cmd,
            v_applied,
            omega_applied,
            sat: drive == 2,
        })
    })
}

/// A robot state of any layout (torque-driven, a velocity base cutting its
/// command or not; with or without the odometry block) and its header.
fn robot_state() -> impl Strategy<Value = (Header, RobotState)> {
    (
        (any::<u32>(), any::<u64>(), 1..1000u32, 0..6u8, finite()),
        (state(), finites::<2>(), finites::<4>(), finites::<4>()),
        (motion(), velocity(), 0.0..10.0f64, odometry()),
    )
        .prop_map(
            |(
                (source, seq, agent, link, t),
                (state, [dv, domega], [e0, e1, z0, z1], [u1, u2, right, left]),
                (leader, velocity, sigma, odometry),
            )| {
                let s = RobotState {
                    t,
                    agent,
                    link: LinkStatus::from_u8(link).unwrap_or_default(),
                    state,
                    dv,
                    domega,
                    e: [e0, e1],
                    z: [z0, z1],
                    u: Input { u1, u2 },
                    tau: Torques { right, left },
                    leader,
                    velocity,
                    sigma,
                    odometry,
                };
                (Header { source, seq }, s)
            },
        )
}

proptest! {
    #[test]
    fn references_round_trip(
        source in any::<u32>(), seq in any::<u64>(), t in finite(),
        v in proptest::array::uniform8(finite()),
    ) {
        let r = Reference {
            t,
            motion: LeaderMotion { p: [v[0], v[1]], dp: [v[2], v[3]], ddp: [v[4], v[5]] },
            speed: v[6],
            turn_rate: v[7],
        };
        let h = Header { source, seq };
        let mut buf = Vec::new();
        encode_reference(&mut buf, h, &r);
        prop_assert_eq!(buf.len(), REFERENCE_LEN);
        prop_assert_eq!(decode(&buf), Ok(Message::Reference(h, r)));
    }

    #[test]
    fn states_round_trip((h, s) in robot_state()) {
        let mut buf = Vec::new();
        encode_state(&mut buf, h, &s);
        let len = if s.odometry.is_some() { STATE_ODOMETRY_LEN } else { STATE_LEN };
        prop_assert_eq!(buf.len(), len);
        prop_assert_eq!(decode(&buf), Ok(Message::State(h, s)));
    }

    /// A state with any reserved byte not 0, or any drive flag bit this
    /// version does not define (4 to 7), is malformed, whatever the rest:
    /// it is another version's or corrupt, and is never half-read (it was
    /// accepted with its reserved bytes ignored).
    #[test]
    fn a_reserved_byte_or_an_unknown_flag_makes_a_state_malformed(
        (h, s) in robot_state(), at in 0..3usize, byte in 1..=255u8, bit in 4..8u32,
    ) {
        let mut buf = Vec::new();
        encode_state(&mut buf, h, &s);
        let mut reserved = buf.clone();
        reserved[HEADER_LEN + 5 + at] = byte;
        prop_assert_eq!(
            decode(&reserved),
            Err(DecodeError::Malformed("reserved bytes must be 0"))
        );
        let mut flagged = buf;
        flagged[HEADER_LEN + 4] |= 1 << bit;
        prop_assert_eq!(
            decode(&flagged),
            Err(DecodeError::Malformed("unknown drive flags"))
        );
    }

    /// Arbitrary bytes decode to an error or a message, never a panic; a
    /// message only if the bytes are exactly one valid encoding.
    #[test]
    fn garbage_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
        if let Ok(m) = decode(&bytes) {
            let mut buf = Vec::new();
            match m {
                Message::Reference(h, r) => encode_reference(&mut buf, h, &r),
                Message::State(h, s) => encode_state(&mut buf, h, &s),
            }
            // Every byte, reserved ones included.
            prop_assert_eq!(buf, bytes);
        }
    }

    /// A truncated message is malformed.
    #[test]
    fn truncation_is_malformed(cut in 0..REFERENCE_LEN) {
        let mut buf = Vec::new();
        encode_reference(&mut buf, Header { source: 1, seq: 2 }, &Reference {
            t: 1.0, motion: LeaderMotion::default(), speed: 0.0, turn_rate: 0.0,
        });
        buf.truncate(cut);
        prop_assert!(matches!(decode(&buf), Err(DecodeError::Malformed(_))));
    }
}

#[test]
fn version_and_magic_are_checked() {
    let mut buf = Vec::new();
    let r = Reference {
        t: 0.5,
        motion: LeaderMotion::default(),
        speed: 0.1,
        turn_rate: 0.0,
    };
    encode_reference(&mut buf, Header { source: 7, seq: 3 }, &r);
    let mut v1 = buf.clone();
    v1[1] = 1;
    assert_eq!(decode(&v1), Err(DecodeError::WrongVersion(1)));
    let mut bad = buf.clone();
    bad[0] = 0;
    assert!(matches!(decode(&bad), Err(DecodeError::Malformed(_))));
    let mut nan = buf.clone();
    nan[HEADER_LEN..HEADER_LEN + 8].copy_from_slice(&f64::NAN.to_le_bytes());
    assert!(matches!(decode(&nan), Err(DecodeError::Malformed(_))));
    let mut kind = buf;
    kind[2] = 9;
    assert!(matches!(decode(&kind), Err(DecodeError::Malformed(_))));
    // A negative position uncertainty is malformed.
    let mut buf = Vec::new();
    let s = RobotState {
        agent: 1,
        sigma: 0.01,
        ..RobotState::default()
    };
    encode_state(&mut buf, Header { source: 7, seq: 3 }, &s);
    assert!(matches!(decode(&buf), Ok(Message::State(_, d)) if d.sigma == 0.01));
    buf[STATE_LEN - 8..].copy_from_slice(&(-0.01f64).to_le_bytes());
    assert!(matches!(decode(&buf), Err(DecodeError::Malformed(_))));
}

/// The odometry block: a state without it keeps the old length (old
/// senders are understood); with it, a negative age, a fix age without
/// its flag, the flag without the block or a block cut short are
/// malformed.
#[test]
fn the_odometry_block_is_optional_and_checked() {
    let h = Header { source: 1, seq: 2 };
    let mut buf = Vec::new();
    let plain = RobotState {
        agent: 2,
        ..RobotState::default()
    };
    encode_state(&mut buf, h, &plain);
    assert_eq!(buf.len(), STATE_LEN);
    assert_eq!(decode(&buf), Ok(Message::State(h, plain)));
    let with = RobotState {
        odometry: Some(OdometryState {
            raw: [1.0, -2.0, 7.0],
            age: 0.02,
            fix_age: None,
        }),
        ..plain
    };
    encode_state(&mut buf, h, &with);
    assert_eq!(buf.len(), STATE_ODOMETRY_LEN);
    assert_eq!(decode(&buf), Ok(Message::State(h, with)));
    let malformed = |b: &[u8]| matches!(decode(b), Err(DecodeError::Malformed(_)));
    let mut bad = buf.clone();
    bad[STATE_LEN + 24..STATE_LEN + 32].copy_from_slice(&(-1.0f64).to_le_bytes());
    assert!(malformed(&bad), "negative age");
    let mut bad = buf.clone();
    bad[STATE_LEN + 32..].copy_from_slice(&0.5f64.to_le_bytes());
    assert!(malformed(&bad), "a fix age without its flag");
    assert!(malformed(&buf[..STATE_LEN]), "the flag without the block");
    let mut bad = buf.clone();
    bad[HEADER_LEN + 4] |= FLAG_FIX_AGE;
    bad[STATE_LEN + 32..].copy_from_slice(&(-0.5f64).to_le_bytes());
    assert!(malformed(&bad), "a negative fix age");
    let mut bad = buf[..STATE_LEN].to_vec();
    bad[HEADER_LEN + 4] = FLAG_FIX_AGE;
    assert!(malformed(&bad), "a fix age flag without odometry");
}

/// A state cut before its drive flags (byte 28) is malformed: reading the
/// flags to choose the length was an index out of bounds (the network fuzz
/// corpus, `tests/fuzz_network.rs`).
#[test]
fn a_state_cut_before_its_flags_is_malformed_not_a_panic() {
    let mut buf = Vec::new();
    let s = RobotState {
        agent: 1,
        ..RobotState::default()
    };
    encode_state(&mut buf, Header { source: 7, seq: 3 }, &s);
    for cut in HEADER_LEN..=HEADER_LEN + 5 {
        assert_eq!(
            decode(&buf[..cut]),
            Err(DecodeError::Malformed("wrong length for a state")),
            "{cut} bytes"
        );
    }
}
