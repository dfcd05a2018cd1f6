use super::*;

#[test]
fn a_borrowed_submit_encodes_as_the_entry() {
    let params = vec![
        Value::Int(-7),
        Value::FloatList(vec![0.5, 1e300]),
        Value::Text("é x".into()),
        Value::Bool(true),
    ];
    let entry = Entry::Submit {
        time: 123_456,
        event: "waypoint".into(),
        params: params.clone(),
        origin: "program/PLN".into(),
        seq: 1 << 40,
    };
    let borrowed = SubmitRecord {
        variant: SUBMIT_VARIANT,
        time: 123_456,
        event: "waypoint",
        params: &params,
        origin: "program/PLN",
        seq: 1 << 40,
    };
    let (mut a, mut b) = (Vec::new(), Vec::new());
    encode_record(&entry, &mut Vec::new(), &mut a).unwrap();
    encode_record(&borrowed, &mut Vec::new(), &mut b).unwrap();
    assert_eq!(a, b);
    assert_eq!(decode_entry(&b[8..]).unwrap(), entry);
}

#[test]
fn a_borrowed_step_encodes_as_the_entry() {
    let params = vec![Value::Int(3), Value::FloatList(vec![0.25, -1e-9])];
    let fired = vec!["R0.answer".to_string(), "MISSION.go".to_string()];
    let actions = vec!["call P0.ping(3, [0.25, -1e-9])".to_string()];
    let (state, deadlines) = (vec![5u64, 1 << 63], vec![None, Some(12_500_000)]);
    let entry = Entry::Step {
        time: 99,
        event: "pong_0".into(),
        params: params.clone(),
        outcome: "processed".into(),
        fired: fired.clone(),
        actions: actions.clone(),
        state: state.clone(),
        deadlines: deadlines.clone(),
    };
    let borrowed = StepParts {
        time: 99,
        event: "pong_0",
        params: &params,
        outcome: "processed",
        fired: &fired[..],
        actions: &actions,
        state: &state,
        deadlines: &deadlines,
    };
    let (mut a, mut b) = (Vec::new(), Vec::new());
    encode_record(&entry, &mut Vec::new(), &mut a).unwrap();
    encode_record(&(STEP_VARIANT, &borrowed), &mut Vec::new(), &mut b).unwrap();
    assert_eq!(a, b);
    assert_eq!(decode_entry(&b[8..]).unwrap(), entry);
}
