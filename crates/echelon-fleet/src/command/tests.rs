use proptest::prelude::*;

use super::*;

/// The operator token of these tests.
fn token() -> OperatorToken {
    OperatorToken::parse("00112233445566778899aabbccddeeff").unwrap_or_else(|e| panic!("{e}"))
}

/// A command from the operator, a resume signed with [`token`].
fn cmd(order: Order, seq: u64) -> FleetCommand {
    let c = FleetCommand::new(order, seq, "operator", "test");
    match order {
        Order::Stop => c,
        Order::Resume => c.signed(&token()),
    }
}

/// A latch holding [`token`].
fn latch() -> Latch {
    Latch::with_token(Some(token()))
}

#[test]
fn commands_round_trip_and_bad_payloads_are_refused() {
    let c = cmd(Order::Stop, 3);
    assert_eq!(FleetCommand::decode(&c.encode()), Ok(c.clone()));
    let json = String::from_utf8(c.encode()).unwrap_or_default();
    assert!(json.contains("\"order\":\"stop\""), "{json}");
    let bad: [&[u8]; 10] = [
            b"",
            b"garbage",
            b"{}",
            br#"{"version":1,"order":"halt","seq":1,"stamp_unix_ns":0,"by":"x","reason":""}"#,
            br#"{"version":1,"order":"stop","seq":-1,"stamp_unix_ns":0,"by":"x","reason":""}"#,
            br#"{"version":1,"order":"stop","seq":1,"stamp_unix_ns":0,"by":"","reason":""}"#,
            br#"{"version":1,"order":"stop","seq":1,"stamp_unix_ns":0,"by":"x","reason":"","x":1}"#,
            br#"{"version":1,"order":"resume","seq":1,"stamp_unix_ns":0,"by":"x","reason":"","proof":"XY"}"#,
            br#"{"version":1,"order":"resume","seq":1,"stamp_unix_ns":0,"by":"x","reason":"","proof":"AB"}"#,
            br#"{"version":1,"order":"resume","seq":1,"stamp_unix_ns":0,"by":"x","reason":"","proof":7}"#,
        ];
    for b in bad {
        assert!(
            matches!(FleetCommand::decode(b), Err(CommandError::Malformed(_))),
            "{}",
            String::from_utf8_lossy(b)
        );
    }
    let v2 = br#"{"version":2,"order":"stop","seq":1,"stamp_unix_ns":0,"by":"x","reason":""}"#;
    assert_eq!(FleetCommand::decode(v2), Err(CommandError::WrongVersion(2)));
    let long = FleetCommand {
        reason: "x".repeat(MAX_REASON + 1),
        ..c.clone()
    };
    assert!(FleetCommand::decode(&long.encode()).is_err());
    assert!(FleetCommand::decode(&vec![b' '; MAX_LEN + 1]).is_err());
    // `new` cuts a long reason to what is accepted.
    let cut = FleetCommand::new(Order::Stop, 1, "operator", &"y".repeat(1000));
    assert!(FleetCommand::decode(&cut.encode()).is_ok());
    // A signed command round-trips with its proof; an unsigned one has
    // none in its JSON.
    let signed = cmd(Order::Resume, 4);
    assert_eq!(signed.proof.len(), PROOF_HEX_LEN);
    assert_eq!(FleetCommand::decode(&signed.encode()), Ok(signed.clone()));
    assert!(!json.contains("proof"), "{json}");
    let longest = FleetCommand {
        by: "b".repeat(MAX_BY),
        reason: "é".repeat(MAX_REASON),
        ..signed.clone()
    };
    assert!(FleetCommand::decode(&longest.encode()).is_ok());
    let too_long = FleetCommand {
        proof: format!("{}0", signed.proof),
        ..signed
    };
    assert!(FleetCommand::decode(&too_long.encode()).is_err());
}

#[test]
fn a_stop_always_holds_and_only_a_later_resume_lifts_it() {
    let mut l = latch();
    assert!(!l.stopped());
    assert_eq!(
        l.latched(),
        Latched {
            stopped: false,
            command: None,
            hazards: HazardSet::EMPTY,
            refused: None,
        }
    );
    assert_eq!(l.on_command(cmd(Order::Stop, 2)), Change::Stopped);
    // An older stop still stops (it is already), the newest number kept.
    assert_eq!(l.on_command(cmd(Order::Stop, 1)), Change::Unchanged);
    assert_eq!(l.stop().map(|s| s.seq), Some(2));
    // A resume numbered at or below the stop is ignored.
    assert_eq!(l.on_command(cmd(Order::Resume, 2)), Change::Unchanged);
    assert!(l.stopped());
    assert_eq!(l.on_command(cmd(Order::Resume, 3)), Change::Resumed);
    assert!(!l.stopped());
    assert_eq!(l.seq(), 3);
    assert!(l.latched().acknowledges(&cmd(Order::Resume, 3)));
    assert!(!l.latched().acknowledges(&cmd(Order::Stop, 3)));
    // A stop numbered below the resume still stops.
    assert_eq!(l.on_command(cmd(Order::Stop, 1)), Change::Stopped);
    assert_eq!(l.on_payload(b"garbage"), Change::Unchanged);
    let c = l.counts();
    assert_eq!(
        (c.received, c.stops, c.resumes, c.refused, c.ignored),
        (1, 2, 1, 1, 1)
    );
}

/// A latch answer's command follows the command key's rules: an
/// unnamed sender or an overlong reason is not a latch answer (it was
/// taken, and a robot then served the unnamed stop on its own latch
/// key; the network fuzz corpus, `tests/fuzz_network.rs`).
#[test]
fn a_latch_answer_carries_only_a_valid_command() {
    for bad in [
        FleetCommand {
            by: String::new(),
            ..cmd(Order::Stop, 4)
        },
        FleetCommand {
            by: "b".repeat(MAX_BY + 1),
            ..cmd(Order::Stop, 4)
        },
        FleetCommand {
            reason: "é".repeat(MAX_REASON + 1),
            ..cmd(Order::Stop, 4)
        },
    ] {
        let answer = Latched {
            stopped: true,
            command: Some(bad.clone()),
            hazards: HazardSet::EMPTY,
            refused: None,
        };
        assert_eq!(Latched::decode(&answer.encode()), None, "{bad:?}");
        let mut l = latch();
        assert_eq!(l.on_hearsay(&answer.encode()), Change::Unchanged);
        assert!(!l.stopped());
    }
    let good = Latched {
        stopped: true,
        command: Some(cmd(Order::Stop, 4)),
        hazards: HazardSet::EMPTY,
        refused: None,
    };
    assert_eq!(Latched::decode(&good.encode()), Some(good.clone()));
    // A refusal is named with a sender and a reason of bounded length.
    let refusal = Refusal {
        seq: 5,
        stamp_unix_ns: 1,
        by: "operator".into(),
        why: NO_VALID_PROOF.into(),
    };
    let refused = Latched {
        refused: Some(refusal.clone()),
        ..good.clone()
    };
    assert_eq!(Latched::decode(&refused.encode()), Some(refused));
    for bad in [
        Refusal {
            by: String::new(),
            ..refusal.clone()
        },
        Refusal {
            why: "w".repeat(MAX_REASON + 1),
            ..refusal.clone()
        },
    ] {
        let answer = Latched {
            refused: Some(bad),
            ..good.clone()
        };
        assert_eq!(Latched::decode(&answer.encode()), None);
    }
    // An answer without the field (an older process) still decodes.
    let old = br#"{"stopped":true,"command":{"version":1,"order":"stop","seq":4,"stamp_unix_ns":0,"by":"operator","reason":""}}"#;
    assert!(Latched::decode(old).is_some_and(|l| l.refused.is_none()));
}

#[test]
fn hearsay_only_stops() {
    let mut l = latch();
    let resumed = Latched {
        stopped: false,
        command: Some(cmd(Order::Resume, 9)),
        hazards: HazardSet::EMPTY,
        refused: None,
    };
    assert_eq!(l.on_hearsay(&resumed.encode()), Change::Unchanged);
    assert_eq!(l.seq(), 0);
    let stopped = Latched {
        stopped: true,
        command: Some(cmd(Order::Stop, 4)),
        hazards: HazardSet::EMPTY,
        refused: None,
    };
    assert_eq!(l.on_hearsay(&stopped.encode()), Change::Stopped);
    assert_eq!(l.on_hearsay(&resumed.encode()), Change::Unchanged);
    assert!(l.stopped());
    // Inconsistent or foreign answers are nothing.
    let liar = Latched {
        stopped: false,
        command: Some(cmd(Order::Stop, 4)),
        hazards: HazardSet::EMPTY,
        refused: None,
    };
    assert_eq!(Latched::decode(&liar.encode()), None);
    assert_eq!(Latched::decode(b"[1,2]"), None);
    assert_eq!(l.on_command(cmd(Order::Resume, 5)), Change::Resumed);
}

/// A resume without a valid proof of the token is refused whatever its
/// number, counted, and named in the latch answer until a resume is
/// obeyed; a latch without a token refuses every resume; a stop needs
/// no proof.
#[test]
fn a_resume_needs_a_valid_proof_of_the_token() {
    let mut l = latch();
    let stop = FleetCommand::new(Order::Stop, 3, "someone", "");
    assert_eq!(l.on_command(stop.clone()), Change::Stopped);
    let unsigned = FleetCommand::new(Order::Resume, 7, "operator", "go");
    assert_eq!(l.on_payload(&unsigned.encode()), Change::Unchanged);
    assert!(l.stopped());
    let refusal = l
        .last_refusal()
        .cloned()
        .unwrap_or_else(|| panic!("refused"));
    assert!(refusal.is_of(&unsigned));
    assert_eq!(
        refusal.to_string(),
        "resume 7 by operator: no valid operator token"
    );
    assert_eq!(l.latched().refused, Some(refusal.clone()));
    assert_eq!(Latched::decode(&l.latched().encode()), Some(l.latched()));
    let other =
        OperatorToken::parse("ffeeddccbbaa99887766554433221100").unwrap_or_else(|e| panic!("{e}"));
    let wrong = FleetCommand::new(Order::Resume, 8, "operator", "go").signed(&other);
    assert_eq!(l.on_command(wrong.clone()), Change::Unchanged);
    assert!(l.last_refusal().is_some_and(|r| r.is_of(&wrong)));
    // A valid proof of another command.
    let copied = FleetCommand {
        seq: 9,
        ..cmd(Order::Resume, 8)
    };
    assert_eq!(l.on_command(copied), Change::Unchanged);
    assert_eq!(l.seq(), 3, "a refused resume's number is not taken");
    assert_eq!(l.counts().unauthorized, 3);
    assert_eq!(
        l.resume_note(Change::Unchanged, CommandCounts::default())
            .as_deref(),
        Some("fleet resume 9 by operator: no valid operator token: refused (3 refused so far)")
    );
    assert_eq!(l.resume_note(Change::Unchanged, l.counts()), None);
    assert_eq!(l.on_command(cmd(Order::Resume, 4)), Change::Resumed);
    assert_eq!(
        l.resume_note(Change::Resumed, l.counts()).as_deref(),
        Some("fleet resume 4 by operator obeyed (reason: \"test\")")
    );
    assert_eq!(l.last_refusal(), None);
    assert_eq!(l.latched().refused, None);
    let c = l.counts();
    assert_eq!(
        (c.stops, c.resumes, c.ignored, c.unauthorized),
        (1, 1, 0, 3)
    );

    // Without a token: stops obeyed, every resume refused.
    let mut alone = Latch::new();
    assert_eq!(alone.on_command(cmd(Order::Stop, 1)), Change::Stopped);
    assert_eq!(alone.on_command(cmd(Order::Resume, 2)), Change::Unchanged);
    assert!(alone.stopped());
    assert_eq!(
        alone.last_refusal().map(ToString::to_string).as_deref(),
        Some("resume 2 by operator: this process has no operator token")
    );
    // A signed stop is a stop.
    let signed_stop = FleetCommand::new(Order::Stop, 5, "operator", "").signed(&token());
    let mut l = latch();
    assert_eq!(l.on_command(signed_stop), Change::Stopped);
}

proptest::proptest! {
    /// What the latch answers changes exactly when its change counter
    /// moves, over any sequence of commands, payloads (good or not) and
    /// hearsay: the runtime, which re-encodes the answer only when the
    /// counter moved, never answers a stale latch.
    #[test]
    fn the_answer_changes_only_when_changes_moves(
        ops in proptest::collection::vec((0u8..4, proptest::bool::ANY, 0u64..6, 0usize..3, proptest::bool::ANY), 1..60),
    ) {
        let mut l = latch();
        for (kind, stop, seq, by, sign) in ops {
            let order = if stop { Order::Stop } else { Order::Resume };
            let c = FleetCommand::new(order, seq, ["operator", "up", "leader"][by], "prop");
            let c = if sign { c.signed(&token()) } else { c };
            let (before, counted) = (l.latched(), l.changes());
            match kind {
                0 => { l.on_command(c); }
                1 => { l.on_payload(&c.encode()); }
                2 => { l.on_payload(&c.encode()[1..]); }
                _ => {
                    let heard = Latched { stopped: stop, command: Some(c), hazards: HazardSet::EMPTY, refused: None };
                    l.on_hearsay(&heard.encode());
                }
            }
            proptest::prop_assert_eq!(l.changes() != counted, l.latched() != before);
            proptest::prop_assert!(l.changes() >= counted);
        }
    }

    /// Over any sequence of stops and resumes (signed with the token,
    /// with another token, unsigned, or signed for another command),
    /// on the command key or in hearsay, with or without a token held:
    /// only a resume with a valid proof ever lifts a stop, and every
    /// other resume is counted as unauthorized and named.
    #[test]
    fn a_resume_without_a_valid_proof_never_lifts_a_stop(
        held in proptest::bool::ANY,
        ops in proptest::collection::vec((0u8..3, proptest::bool::ANY, 0u64..8, 0u8..4), 1..60),
    ) {
        let other = OperatorToken::parse("0f0e0d0c0b0a09080706050403020100")
            .unwrap_or_else(|e| panic!("{e}"));
        let mut l = if held { latch() } else { Latch::new() };
        for (kind, stop, seq, proof) in ops {
            let order = if stop { Order::Stop } else { Order::Resume };
            let unsigned = FleetCommand::new(order, seq, "operator", "prop");
            let c = match proof {
                0 => unsigned.clone().signed(&token()),
                1 => unsigned.clone().signed(&other),
                2 => FleetCommand { seq: seq + 1, ..unsigned.clone().signed(&token()) },
                _ => unsigned.clone(),
            };
            let valid = held && proof == 0;
            let (was_stopped, before) = (l.stopped(), l.counts());
            let change = match kind {
                0 => l.on_command(c.clone()),
                1 => l.on_payload(&c.encode()),
                _ => {
                    let heard = Latched {
                        stopped: stop,
                        command: Some(c.clone()),
                        hazards: HazardSet::EMPTY,
                        refused: None,
                    };
                    l.on_hearsay(&heard.encode())
                }
            };
            if stop {
                proptest::prop_assert!(l.stopped(), "a stop always stops");
            } else if was_stopped && !l.stopped() {
                proptest::prop_assert!(valid && kind < 2, "{:?} lifted a stop", c);
                proptest::prop_assert_eq!(change, Change::Resumed);
            }
            let refused = l.counts().unauthorized - before.unauthorized;
            let expected = u64::from(!stop && !valid && kind < 2);
            proptest::prop_assert_eq!(refused, expected, "{:?}", c);
            if expected == 1 {
                proptest::prop_assert!(l.last_refusal().is_some_and(|r| r.is_of(&c)));
                proptest::prop_assert_eq!(l.stopped(), was_stopped);
                proptest::prop_assert_eq!(change, Change::Unchanged);
            }
        }
    }
}

/// The token of 16 given bytes.
fn token_of(bytes: [u8; 16]) -> OperatorToken {
    let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
    OperatorToken::parse(&hex).unwrap()
}

fn command() -> impl Strategy<Value = FleetCommand> {
    (
        any::<bool>(),
        any::<u64>(),
        any::<u64>(),
        "[a-z0-9-]{1,64}",
        "\\PC{0,40}",
    )
        .prop_map(|(stop, seq, stamp, by, reason)| {
            let order = if stop { Order::Stop } else { Order::Resume };
            FleetCommand {
                stamp_unix_ns: stamp,
                ..FleetCommand::new(order, seq, &by, &reason)
            }
        })
}

/// The proof's bytes are fixed (scripts that sign a resume themselves,
/// `scripts/interop/ros2dds/check_run.py`, make the same).
#[test]
fn the_proof_is_hmac_sha256_of_the_fields_length_prefixed() {
    let t = OperatorToken::parse("000102030405060708090a0b0c0d0e0f").unwrap();
    let c = FleetCommand {
        stamp_unix_ns: 5,
        ..FleetCommand::new(Order::Resume, 7, "operator", "ok")
    };
    let mut expected = SIGNED_DOMAIN.to_vec();
    expected.extend([0, 0, 0, 1]);
    expected.extend([0, 0, 0, 6]);
    expected.extend(b"resume");
    expected.extend([0, 0, 0, 0, 0, 0, 0, 7]);
    expected.extend([0, 0, 0, 0, 0, 0, 0, 5]);
    expected.extend([0, 0, 0, 8]);
    expected.extend(b"operator");
    expected.extend([0, 0, 0, 2]);
    expected.extend(b"ok");
    assert_eq!(c.signed_bytes(), expected);
    let p = t.sign(&c.signed_bytes());
    assert_eq!(p.len(), PROOF_HEX_LEN);
    // HMAC-SHA256 keyed by the token's 16 bytes, by ring directly.
    let key_bytes: Vec<u8> = (0u8..16).collect();
    let key = ring::hmac::Key::new(ring::hmac::HMAC_SHA256, &key_bytes);
    let tag = ring::hmac::sign(&key, &expected);
    let hex: String = tag.as_ref().iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(p, hex);
    // As check_run.py's `command_proof` makes it.
    assert_eq!(
        p,
        "9b27d875f2fafd01c231a8de3679dd23c6e439e123c1b52205198e3851e05dde"
    );
    // The proof itself is not signed: a signed command verifies.
    assert!(c.clone().signed(&t).verified_by(&t));
    assert!(!c.verified_by(&t));
}

proptest! {
        /// A signed command verifies with its token, and no longer once
        /// any field changes, with another token, or with a mangled proof.
        #[test]
        fn only_the_signed_command_with_its_token_verifies(
            c in command(),
            key in any::<[u8; 16]>(),
            other in any::<[u8; 16]>(),
            seq in any::<u64>(),
            stamp in any::<u64>(),
            by in "[a-z0-9-]{1,64}",
            reason in "\\PC{0,40}",
            at in 0usize..PROOF_HEX_LEN,
        ) {
            let t = token_of(key);
            let signed = c.clone().signed(&t);
            prop_assert!(signed.verified_by(&t));
            prop_assert_eq!(FleetCommand::decode(&signed.encode()), Ok(signed.clone()));
            prop_assert!(FleetCommand::decode(&signed.encode()).unwrap().verified_by(&t));
            // The text of the token round-trips.
            prop_assert_eq!(OperatorToken::parse(&t.to_hex()).unwrap(), t.clone());
            let changed = [
                FleetCommand { seq, ..signed.clone() },
                FleetCommand { stamp_unix_ns: stamp, ..signed.clone() },
                FleetCommand { by: by.clone(), ..signed.clone() },
                FleetCommand { reason: reason.clone(), ..signed.clone() },
                FleetCommand {
                    order: if signed.order == Order::Stop { Order::Resume } else { Order::Stop },
                    ..signed.clone()
                },
                FleetCommand { version: signed.version + 1, ..signed.clone() },
            ];
            for x in changed {
                prop_assert_eq!(x.verified_by(&t), x == signed, "{:?}", x);
            }
            prop_assert_eq!(signed.verified_by(&token_of(other)), other == key);
            let mut mangled = signed.proof.clone().into_bytes();
            mangled[at] = if mangled[at] == b'0' { b'1' } else { b'0' };
            let mangled = FleetCommand { proof: String::from_utf8(mangled).unwrap(), ..signed.clone() };
            prop_assert!(!mangled.verified_by(&t));
            let short = FleetCommand { proof: signed.proof[..at].to_owned(), ..signed.clone() };
            prop_assert!(!short.verified_by(&t));
        }

}
