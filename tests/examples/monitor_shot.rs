//! A screenshot of a running `petrel monitor`, as scripts/main.sh takes them (under target/):
//! headless Chromium under chromedriver (Debian's `chromium` and `chromium-driver`) opens the
//! page, waits until it is in step with the player, shows at least STEPS steps in its event
//! log and has drawn its view, and saves the window as PNG.
//!
//! `monitor_shot URL OUT.png [STEPS] [WIDTHxHEIGHT]`: the URL says the view
//! (`/?view=overview`, `/?net=NAME`, `/?view=map`, `/?view=all`); the window is 1600x1000 by
//! default.

use petrel_tests::web::Browser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(url), Some(out)) = (args.first(), args.get(1)) else {
        eprintln!("usage: monitor_shot URL OUT.png [STEPS] [WIDTHxHEIGHT]");
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
    let size = args.get(3).map(|s| {
        s.split_once('x')
            .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
    });
    let (width, height) = match size {
        None => (1600, 1000),
        Some(Some(s)) => s,
        Some(None) => {
            eprintln!("the size is WIDTHxHEIGHT, in pixels");
            return ExitCode::from(2);
        }
    };
    if !petrel_tests::web::browser_available() {
        return ExitCode::from(2);
    }
    let b = Browser::start_sized(width, height);
    b.open(url);
    b.wait_ready();
    let shown = b.wait_for(
        30.0,
        "return document.body.dataset.synced === 'true' ? document.querySelectorAll('#log tbody tr').length : -1",
        |v| v.as_i64().is_some_and(|n| n >= steps as i64),
    );
    // The map is drawn once fetched.
    b.wait_for(
        10.0,
        "return document.body.dataset.view !== 'map' || !!document.body.dataset.map",
        |v| v == true,
    );
    b.screenshot(&std::path::PathBuf::from(out));
    println!("{out}: the monitor with {shown} steps in its log");
    ExitCode::SUCCESS
}
