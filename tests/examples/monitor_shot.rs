//! A screenshot of a running `petrel monitor`, as scripts/main.sh takes it for the README:
//! headless Chromium under chromedriver (Debian's `chromium` and `chromium-driver`) opens the
//! page, waits until it is in step with the player and shows at least N steps in its event
//! log, and saves the window as PNG.
//!
//! `monitor_shot URL OUT.png [STEPS] [NET]` (NET: select that net, the view zoomed on it)

use petrel_tests::web::Browser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(url), Some(out)) = (args.first(), args.get(1)) else {
        eprintln!("usage: monitor_shot URL OUT.png [STEPS]");
        return ExitCode::from(2);
    };
    let steps: u64 = match args.get(2).map(|s| s.parse()) {
        None => 1,
        Some(Ok(n)) => n,
        Some(Err(_)) => {
            eprintln!("STEPS is a number of steps");
            return ExitCode::from(2);
        }
    };
    if !petrel_tests::web::browser_available() {
        return ExitCode::from(2);
    }
    let b = Browser::start();
    b.open(url);
    b.wait_ready();
    let shown = b.wait_for(
        30.0,
        "return document.body.dataset.synced === 'true' ? document.querySelectorAll('#log tbody tr').length : -1",
        |v| v.as_i64().is_some_and(|n| n >= steps as i64),
    );
    if let Some(net) = args.get(3) {
        let net = serde_json::to_string(net).unwrap_or_default();
        b.eval(&format!(
            "const li = document.querySelector('#netlist li[data-net=' + JSON.stringify({net}) + ']'); if (li) li.click(); return null"
        ));
    }
    b.screenshot(&std::path::PathBuf::from(out));
    println!("{out}: the monitor with {shown} steps in its log");
    ExitCode::SUCCESS
}
