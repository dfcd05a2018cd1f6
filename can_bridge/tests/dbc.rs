//! DBC decoding and encoding against frames computed by hand.

use petrel_can_bridge::dbc::{
    ByteOrder, DbcErrorKind, DecodeOutcome, DecodedMessage, EncodeError, ValueError, ValueKind,
};
use petrel_can_bridge::frame::{CanId, Frame};
use petrel_can_bridge::Dbc;
use proptest::prelude::*;

fn auv() -> Dbc {
    Dbc::load(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/auv/auv.dbc"
    )))
    .expect("the bench DBC loads")
}

fn std_id(id: u16) -> CanId {
    CanId::Standard(id)
}

/// Decodes and returns `(signal name, physical)` pairs.
fn decode(dbc: &Dbc, frame: &Frame) -> Vec<(String, f64)> {
    match dbc.decode(frame) {
        DecodeOutcome::Message(DecodedMessage { signals, .. }) => signals
            .iter()
            .map(|s| (dbc.signal(s.signal).unwrap().name.clone(), s.physical))
            .collect(),
        other => panic!("not decoded: {other:?}"),
    }
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

#[test]
fn the_bench_dbc_reads_with_its_attributes() {
    let dbc = auv();
    let depth = dbc.message(dbc.message_by_name("Depth").unwrap()).unwrap();
    assert_eq!(depth.id, std_id(0x200));
    assert_eq!(depth.size, 3);
    assert_eq!(depth.cycle_time_ms, Some(100));
    let d = &depth.signals[0];
    assert_eq!(d.byte_order, ByteOrder::BigEndian);
    assert_eq!(d.kind, ValueKind::Unsigned);
    assert_eq!((d.factor, d.offset), (0.01, -5.0));
    assert_eq!((d.min, d.max), (Some(-5.0), Some(650.0)));
    // Messages without GenMsgCycleTime take the default, 0: not periodic.
    let cmd = dbc
        .message(dbc.message_by_name("DepthCmd").unwrap())
        .unwrap();
    assert_eq!(cmd.cycle_time_ms, None);
    let state = dbc
        .signal(dbc.signal_ref("Battery.state").unwrap())
        .unwrap();
    assert_eq!(state.label(2), Some("charging"));
    assert_eq!(state.raw_of("empty"), Some(4));
    let enable = dbc
        .signal(dbc.signal_ref("ThrusterCmd.enable").unwrap())
        .unwrap();
    assert_eq!(enable.start_value, Some(0.0));
    let nav = dbc
        .message(dbc.message_by_name("NavTime").unwrap())
        .unwrap();
    assert_eq!(nav.id, CanId::Extended(0x18FF_0100));
    let range = dbc.signal(dbc.signal_ref("Sonar.range").unwrap()).unwrap();
    assert_eq!(range.kind, ValueKind::Float32);
}

#[test]
fn big_endian_unsigned_with_scaling_and_offset() {
    let dbc = auv();
    // Depth.depth: start bit 7, 16 bits, Motorola: the MSB is bit 7 of byte 0, so the value
    // is bytes 0..2 read big-endian. 30.00 m -> raw (30 - (-5)) / 0.01 = 3500 = 0x0DAC.
    // Depth.status: start bit 23, 8 bits, Motorola: byte 2. 0x5A.
    let frame = Frame::data(std_id(0x200), &[0x0D, 0xAC, 0x5A]).unwrap();
    let got = decode(&dbc, &frame);
    assert_eq!(got[0].0, "depth");
    assert!(close(got[0].1, 30.0), "{got:?}");
    assert_eq!(got[1], ("status".to_owned(), 90.0));
    let encoded = dbc
        .encode("Depth", &[("depth", 30.0), ("status", 90.0)])
        .unwrap();
    assert_eq!(encoded.payload(), &[0x0D, 0xAC, 0x5A]);
    assert_eq!(encoded.id(), std_id(0x200));
    // The smallest value: raw 0 is -5 m.
    let zero = Frame::data(std_id(0x200), &[0, 0, 0]).unwrap();
    assert!(close(decode(&dbc, &zero)[0].1, -5.0));
}

#[test]
fn signed_little_and_big_endian() {
    let dbc = auv();
    // Ahrs.heading 0|16@1+ (0.01): 123.45 -> 12345 = 0x3039, little-endian: 39 30.
    // Ahrs.pitch 23|16@0- (0.01): -12.34 -> -1234 -> 0x10000 - 1234 = 0xFB2E; its MSB is bit 7
    //   of byte 2, so bytes 2..4 big-endian: FB 2E.
    // Ahrs.roll 32|16@1- (0.01): -45.00 -> -4500 -> 0x10000 - 4500 = 0xEE6C, little-endian
    //   from byte 4: 6C EE.
    let bytes = [0x39, 0x30, 0xFB, 0x2E, 0x6C, 0xEE];
    let got = decode(&dbc, &Frame::data(std_id(0x210), &bytes).unwrap());
    assert!(close(got[0].1, 123.45), "{got:?}");
    assert!(close(got[1].1, -12.34), "{got:?}");
    assert!(close(got[2].1, -45.0), "{got:?}");
    let f = dbc
        .encode(
            "Ahrs",
            &[("heading", 123.45), ("pitch", -12.34), ("roll", -45.0)],
        )
        .unwrap();
    assert_eq!(f.payload(), &bytes);

    // ThrusterCmd: rpm_left -1500 -> 0xFA24 (LE: 24 FA), rpm_right 1500 = 0x05DC (LE: DC 05),
    // enable 1 at bit 32: byte 4 = 01.
    let f = dbc
        .encode(
            "ThrusterCmd",
            &[
                ("rpm_left", -1500.0),
                ("rpm_right", 1500.0),
                ("enable", 1.0),
            ],
        )
        .unwrap();
    assert_eq!(f.payload(), &[0x24, 0xFA, 0xDC, 0x05, 0x01]);
    assert_eq!(f.id(), std_id(0x100));
    let got = decode(&dbc, &f);
    assert_eq!(got[0].1, -1500.0);
    assert_eq!(got[1].1, 1500.0);
}

#[test]
fn value_tables_and_signed_current() {
    let dbc = auv();
    // Battery: voltage 24.5 V -> 2450 = 0x0992 (LE 92 09); current -12.5 A -> -1250 ->
    // 0xFB1E (LE 1E FB); state "charging" = 2 in bits 32..35: byte 4 = 02.
    let bytes = [0x92, 0x09, 0x1E, 0xFB, 0x02];
    let frame = Frame::data(std_id(0x230), &bytes).unwrap();
    let DecodeOutcome::Message(m) = dbc.decode(&frame) else {
        panic!("not decoded")
    };
    let state = m.signals[2];
    assert_eq!(state.raw, 2);
    assert_eq!(
        dbc.signal(state.signal).unwrap().label(state.raw),
        Some("charging")
    );
    let charging = dbc
        .signal(dbc.signal_ref("Battery.state").unwrap())
        .unwrap()
        .value_of("charging")
        .unwrap();
    let f = dbc
        .encode(
            "Battery",
            &[("voltage", 24.5), ("current", -12.5), ("state", charging)],
        )
        .unwrap();
    assert_eq!(f.payload(), &bytes);
}

#[test]
fn multiplexed_signals_follow_the_switch() {
    let dbc = auv();
    // page = 1 (byte 0); temp_a m1 8|16@1- (0.1): 25.3 -> 253 = 0x00FD (LE FD 00);
    // temp_b m1 24|16@1- (0.1): -10.0 -> -100 -> 0xFF9C (LE 9C FF).
    let bytes = [0x01, 0xFD, 0x00, 0x9C, 0xFF];
    let got = decode(&dbc, &Frame::data(std_id(0x250), &bytes).unwrap());
    let names: Vec<&str> = got.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["page", "temp_a", "temp_b"]);
    assert!(close(got[1].1, 25.3) && close(got[2].1, -10.0), "{got:?}");
    let f = dbc
        .encode(
            "BatteryCells",
            &[("page", 1.0), ("temp_a", 25.3), ("temp_b", -10.0)],
        )
        .unwrap();
    assert_eq!(f.payload(), &bytes);
    // page 0: the cells. cell_a 3.7 V -> 3700 = 0x0E74 (LE 74 0E), cell_b 3.65 -> 0x0E42.
    let got = decode(
        &dbc,
        &Frame::data(std_id(0x250), &[0x00, 0x74, 0x0E, 0x42, 0x0E]).unwrap(),
    );
    let names: Vec<&str> = got.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["page", "cell_a", "cell_b"]);
    assert!(close(got[1].1, 3.7) && close(got[2].1, 3.65));
    // A signal the switch does not select is refused, by name.
    let e = dbc
        .encode(
            "BatteryCells",
            &[
                ("page", 1.0),
                ("temp_a", 25.3),
                ("temp_b", 1.0),
                ("cell_a", 3.0),
            ],
        )
        .unwrap_err();
    assert!(
        matches!(e, EncodeError::NotSelected { ref signal, needs: 0, .. } if signal == "cell_a"),
        "{e}"
    );
}

/// A simulator reads a signal of a decoded frame by its name: those the frame carries, none
/// that the switch left out or that the message lacks.
#[test]
fn a_decoded_signal_is_read_by_its_name() {
    let dbc = auv();
    let frame = Frame::data(std_id(0x250), &[0x01, 0xFD, 0x00, 0x9C, 0xFF]).unwrap();
    let DecodeOutcome::Message(dm) = dbc.decode(&frame) else {
        panic!("not decoded");
    };
    assert!(close(dm.value(&dbc, "temp_a").unwrap(), 25.3));
    assert!(close(dm.value(&dbc, "temp_b").unwrap(), -10.0));
    assert_eq!(dm.value(&dbc, "page"), Some(1.0));
    assert_eq!(dm.value(&dbc, "cell_a"), None, "not selected by the switch");
    assert_eq!(dm.value(&dbc, "depth"), None, "another message's signal");
}

#[test]
fn sixty_four_bits_extended_and_float() {
    let dbc = auv();
    // NavTime (29-bit 0x18FF0100): time_us 0|64@1+ = 0x0102030405060708, LE: 08 07 ... 01.
    let f = Frame::data(CanId::Extended(0x18FF_0100), &[8, 7, 6, 5, 4, 3, 2, 1]).unwrap();
    let DecodeOutcome::Message(m) = dbc.decode(&f) else {
        panic!()
    };
    assert_eq!(m.signals[0].raw, 0x0102_0304_0506_0708);
    let all_ones = Frame::data(CanId::Extended(0x18FF_0100), &[0xFF; 8]).unwrap();
    let DecodeOutcome::Message(m) = dbc.decode(&all_ones) else {
        panic!()
    };
    assert_eq!(m.signals[0].raw, i128::from(u64::MAX));
    // The identifier's format is part of it: 29-bit 0x100 is not ThrusterCmd (11-bit 0x100).
    assert!(matches!(
        dbc.decode(&Frame::data(CanId::Extended(0x100), &[0; 5]).unwrap()),
        DecodeOutcome::UnknownId(CanId::Extended(0x100))
    ));
    // Sonar.range is an IEEE single: 12.5 = 0x41480000, LE 00 00 48 41.
    let f = dbc.encode("Sonar", &[("range", 12.5)]).unwrap();
    assert_eq!(f.payload(), &[0x00, 0x00, 0x48, 0x41]);
    assert_eq!(decode(&dbc, &f)[0].1, 12.5);
}

#[test]
fn unaligned_layouts_as_cantools_lays_them_out() {
    let text = r#"VERSION ""
NS_ :
BS_:
BU_: A
BO_ 16 Odd: 2 A
 SG_ be : 3|10@0+ (1,0) [0|1023] "" A
BO_ 17 OddLe: 2 A
 SG_ le : 4|12@1+ (1,0) [0|4095] "" A
BO_ 18 Small: 1 A
 SG_ nibble : 0|4@1+ (1,0) [0|100] "" A
"#;
    let dbc = Dbc::parse(text).unwrap();
    // Big-endian, start bit 3, 10 bits: bits 3..0 of byte 0 then bits 7..2 of byte 1.
    // 0x2AB = 10_1010_1011: 1010 -> byte 0 = 0x0A; 101011 -> byte 1 = 1010_1100 = 0xAC.
    let f = dbc.encode("Odd", &[("be", f64::from(0x2AB))]).unwrap();
    assert_eq!(f.payload(), &[0x0A, 0xAC]);
    assert_eq!(decode(&dbc, &f)[0].1, f64::from(0x2AB));
    // Little-endian, start bit 4, 12 bits: 0xABC -> low nibble C in bits 4..7 of byte 0
    // (0xC0), then 0xAB in byte 1.
    let f = dbc.encode("OddLe", &[("le", f64::from(0xABC))]).unwrap();
    assert_eq!(f.payload(), &[0xC0, 0xAB]);
    assert_eq!(decode(&dbc, &f)[0].1, f64::from(0xABC));
    // [0|100] in 4 bits: 20 is in range but needs raw 20 > 15: refused, not clamped.
    let e = dbc.encode("Small", &[("nibble", 20.0)]).unwrap_err();
    assert!(
        matches!(&e, EncodeError::Value { signal, error: ValueError::NotRepresentable { .. }, .. } if signal == "nibble"),
        "{e}"
    );
    assert!(e.to_string().contains("Small.nibble"), "{e}");
}

#[test]
fn out_of_range_values_are_refused_naming_the_signal() {
    let dbc = auv();
    let e = dbc
        .encode(
            "ThrusterCmd",
            &[("rpm_left", 3001.0), ("rpm_right", 0.0), ("enable", 1.0)],
        )
        .unwrap_err();
    assert!(
        matches!(&e, EncodeError::Value { signal, error: ValueError::OutOfRange { min, max }, .. }
            if signal == "rpm_left" && *min == -3000.0 && *max == 3000.0),
        "{e:?}"
    );
    assert_eq!(
        e.to_string(),
        "signal `ThrusterCmd.rpm_left`: 3001 is outside its range [-3000, 3000]"
    );
    // The bounds themselves are fine.
    assert!(dbc
        .encode(
            "ThrusterCmd",
            &[
                ("rpm_left", -3000.0),
                ("rpm_right", 3000.0),
                ("enable", 0.0)
            ]
        )
        .is_ok());
    let e = dbc.encode("DepthCmd", &[("target", f64::NAN)]).unwrap_err();
    assert!(matches!(
        e,
        EncodeError::Value {
            error: ValueError::NotFinite,
            ..
        }
    ));
    let e = dbc.encode("DepthCmd", &[]).unwrap_err();
    assert!(matches!(e, EncodeError::MissingSignal { ref signal, .. } if signal == "target"));
    let e = dbc
        .encode("DepthCmd", &[("target", 1.0), ("tagret", 2.0)])
        .unwrap_err();
    assert!(matches!(e, EncodeError::UnknownSignal { .. }));
    assert!(matches!(
        dbc.encode("Nope", &[]),
        Err(EncodeError::UnknownMessage(_))
    ));
}

#[test]
fn frames_that_do_not_fit_are_outcomes() {
    let dbc = auv();
    assert_eq!(
        dbc.decode(&Frame::data(std_id(0x7FF), &[1, 2]).unwrap()),
        DecodeOutcome::UnknownId(std_id(0x7FF))
    );
    let depth = dbc.message_by_name("Depth").unwrap();
    assert_eq!(
        dbc.decode(&Frame::data(std_id(0x200), &[1, 2]).unwrap()),
        DecodeOutcome::WrongLength {
            message: depth,
            expected: 3,
            got: 2
        }
    );
    assert_eq!(
        dbc.decode(&Frame::remote(std_id(0x200), 3).unwrap()),
        DecodeOutcome::Remote(std_id(0x200))
    );
    assert_eq!(
        dbc.decode(&Frame::error(0x40, [0; 8]).unwrap()),
        DecodeOutcome::Error
    );
}

#[test]
fn invalid_dbcs_are_errors_with_a_place() {
    let base = "VERSION \"\"\nNS_ :\nBS_:\nBU_: A\n";
    let case = |body: &str| Dbc::parse(&format!("{base}{body}")).unwrap_err();
    let e = case("BO_ 16 M: 1 A\n SG_ s : 4|8@1+ (1,0) [0|1] \"\" A\n");
    assert!(
        matches!(&e.kind, DbcErrorKind::OutsideFrame { signal, needs: 2, size: 1, .. } if signal == "s"),
        "{e}"
    );
    // The offset points at the signal's declaration.
    let text = format!("{base}BO_ 16 M: 1 A\n SG_ s : 4|8@1+ (1,0) [0|1] \"\" A\n");
    assert!(text[e.offset.unwrap()..].starts_with("s : 4|8"));
    let e = case("BO_ 16 M: 1 A\n SG_ s : 0|8@1+ (0,0) [0|1] \"\" A\n");
    assert!(matches!(e.kind, DbcErrorKind::BadFactor { .. }), "{e}");
    let e = case("BO_ 16 M: 1 A\n SG_ s : 0|0@1+ (1,0) [0|1] \"\" A\n");
    assert!(matches!(e.kind, DbcErrorKind::BadSize { .. }), "{e}");
    let e = case("BO_ 16 M: 1 A\nBO_ 16 N: 1 A\n");
    assert!(matches!(e.kind, DbcErrorKind::DuplicateId { .. }), "{e}");
    let e = case("BO_ 16 M: 1 A\n SG_ s m1 : 0|8@1+ (1,0) [0|1] \"\" A\n");
    assert!(
        matches!(e.kind, DbcErrorKind::UnsupportedMultiplexing { .. }),
        "{e}"
    );
    let e = case("BO_ 16 M: 72 A\n");
    assert!(matches!(e.kind, DbcErrorKind::MessageTooLong { .. }), "{e}");
    // A syntax error has a line and an offset.
    let e = Dbc::parse("VERSION \"\"\nNS_ :\nBS_:\nBU_: A\nBO_ sixteen M: 1 A\n").unwrap_err();
    assert!(matches!(e.kind, DbcErrorKind::Syntax(_)), "{e}");
    assert!(e.to_string().contains("line 5"), "{e}");
    assert!(e.offset.is_some());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Decoding never panics, whatever the frame.
    #[test]
    fn decoding_garbage_never_panics(id in 0u32..0x800, data in proptest::collection::vec(any::<u8>(), 0..=8)) {
        let dbc = auv();
        let f = Frame::data(CanId::standard(id).unwrap(), &data).unwrap();
        let _ = dbc.decode(&f);
    }

    /// Encoding a decoded frame gives the frame back (for every signal's bits in range).
    #[test]
    fn ahrs_round_trips(heading in 0u16..35999, pitch in -9000i16..=9000, roll in -18000i16..=18000) {
        let dbc = auv();
        let values = [
            ("heading", f64::from(heading) * 0.01),
            ("pitch", f64::from(pitch) * 0.01),
            ("roll", f64::from(roll) * 0.01),
        ];
        let f = dbc.encode("Ahrs", &values).unwrap();
        let back = decode(&dbc, &f);
        for ((_, want), (_, got)) in values.iter().zip(&back) {
            prop_assert!((want - got).abs() < 1e-6);
        }
        let again = dbc.encode("Ahrs", &back.iter().map(|(n, v)| (n.as_str(), *v)).collect::<Vec<_>>()).unwrap();
        prop_assert_eq!(again, f);
    }

    /// Parsing any text never panics.
    #[test]
    fn parsing_garbage_never_panics(text in "(VERSION \"\"\n|NS_ :\n|BS_:\n|BU_: A\n|BO_ [0-9]{1,4} M: [0-9] A\n| SG_ s[ mM0-9]* : [0-9]{1,2}\\|[0-9]{1,2}@[01][+-] \\([0-9.-]+,[0-9.-]+\\) \\[[0-9.-]+\\|[0-9.-]+\\] \"\" A\n|[ -~]{0,12}\n){0,8}") {
        let _ = Dbc::parse(&text);
    }
}

/// Physical values of integer signals read with the decimals of their factor and offset, not
/// with the noise of binary floating point: raw 549 at 0.01 m per bit, offset -5 m, is 0.49 m.
#[test]
fn physical_values_have_the_decimals_of_their_scaling() {
    let dbc = auv();
    // Depth: 16 bits big-endian from bit 7, 0.01 m, offset -5 m; raw 549 = 0x0225.
    let frame = Frame::data(CanId::Standard(0x200), &[0x02, 0x25, 0x00]).unwrap();
    let petrel_can_bridge::dbc::DecodeOutcome::Message(m) = dbc.decode(&frame) else {
        panic!("Depth decodes");
    };
    assert_eq!(m.signals[0].raw, 549);
    assert_eq!(m.signals[0].physical, 0.49);
    assert_eq!(format!("{}", m.signals[0].physical), "0.49");
    // Battery voltage, 0.01 V: raw 2190 is 21.9 V exactly as written.
    let v = dbc
        .encode(
            "Battery",
            &[("voltage", 21.9), ("current", 0.0), ("state", 1.0)],
        )
        .unwrap();
    let petrel_can_bridge::dbc::DecodeOutcome::Message(m) = dbc.decode(&v) else {
        panic!("Battery decodes");
    };
    assert_eq!(m.signals[0].physical, 21.9);
}
