//! The UGV pair's programs (`ugv planner`, `ugv moves`) as real processes over real iceoryx2,
//! driven by a fake player in the test process: what missions/ugv's nets rely on.

use petrel_ipc::Value;
use petrel_tests::programs::{FakePlayer, Proc, Stream, TestVehicle};

const UGV: &str = env!("CARGO_BIN_EXE_ugv");

fn text(t: &str) -> Value {
    Value::Text(t.to_owned())
}

#[test]
fn the_planner_gives_each_robot_its_moves_then_plan_done_and_a_replan_goes_on() {
    let v = TestVehicle::new();
    let _planner = Proc::spawn(UGV, &["planner", v.name()]);
    let mut player = FakePlayer::join(&v.vehicle);
    let mut r1 = Vec::new();
    for _ in 0..4 {
        player.call("PLANNER", "next", vec![text("r1")]);
        let params = player.expect("next_move");
        assert_eq!(params[0], text("r1"));
        r1.push(params[1].clone());
    }
    // Both robots reach the bottleneck at their second move.
    let moves = [
        "forward",
        "enter_bottleneck",
        "turn_left",
        "follow_right_wall",
    ];
    assert_eq!(r1, moves.map(text));
    player.call("PLANNER", "next", vec![text("r1")]);
    assert_eq!(player.expect("plan_done"), [text("r1")]);
    // The other robot's plan is its own, from its start.
    player.call("PLANNER", "replan", vec![text("r2")]);
    assert_eq!(player.expect("next_move"), [text("r2"), text("forward")]);
    player.call("PLANNER", "next", vec![text("r2")]);
    assert_eq!(
        player.expect("next_move"),
        [text("r2"), text("enter_bottleneck")]
    );
}

#[test]
fn a_robot_executes_a_move_then_says_move_done_and_refuses_an_unknown_move() {
    let v = TestVehicle::new();
    let mut robot = Proc::spawn(UGV, &["moves", v.name(), "r1", "MOVES_R1", "20"]);
    let mut player = FakePlayer::join(&v.vehicle);
    player.call("MOVES_R1", "execute", vec![text("forward")]);
    robot.wait_for(Stream::Out, "r1: forward");
    assert_eq!(player.expect("move_done"), [text("r1")]);
    player.call("MOVES_R1", "execute", vec![text("fly")]);
    robot.wait_for(Stream::Err, "`fly` is not an elementary move");
}

#[test]
fn without_its_arguments_it_prints_its_usage_and_exits_2() {
    let out = std::process::Command::new(UGV).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("usage: ugv planner VEHICLE"));
}
