//! The SDK's smallest example, `echo`, as a real process over real iceoryx2, driven by a fake
//! player in the test process.

use petrel_ipc::Value;
use petrel_tests::example_bin;
use petrel_tests::programs::{FakePlayer, Proc, Stream, TestVehicle};

#[test]
fn echo_answers_ping_with_pong() {
    let v = TestVehicle::new();
    let mut echo = Proc::spawn(example_bin("echo"), &[v.name(), "ECHO"]);
    let mut player = FakePlayer::join(&v.vehicle);
    player.call("ECHO", "ping", vec![Value::Int(7), Value::Text("x".into())]);
    assert_eq!(
        player.expect("pong"),
        [Value::Int(7), Value::Text("x".into())]
    );
    echo.wait_for(Stream::Out, r#"echo: ECHO.ping(7, "x")"#);
    echo.signal("INT");
    assert!(echo.wait_exit().success());
}
