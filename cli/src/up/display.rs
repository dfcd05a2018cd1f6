//! What `petrel up` shows while the vehicle runs: one status line per process, redrawn in
//! place about twice a second on a terminal, or printed as plain lines, one each time a
//! process's state changes, when the output is a file or a pipe (logs and scripts want every
//! change once, not a frame every half second). Messages (sends, restarts, the end) go above
//! the status lines.

use std::io::Write;
use std::time::{Duration, Instant};

/// How often the block of status lines is redrawn on a terminal.
const REDRAW: Duration = Duration::from_millis(500);

/// One process's line: `key` says when it changed (state, pid, restarts), `text` is shown.
pub struct Line {
    /// What must change for a plain-line output to print the line again.
    pub key: String,
    /// The line itself.
    pub text: String,
}

/// The status output (standard output).
pub struct Display {
    tty: bool,
    t0: Instant,
    /// Lines of the block drawn last (terminal).
    drawn: usize,
    last_draw: Option<Instant>,
    /// The last key printed for each process (plain lines).
    keys: Vec<String>,
}

impl Display {
    /// A display on standard output, drawn in place when it is a terminal.
    pub fn new(t0: Instant) -> Self {
        Display {
            tty: std::io::IsTerminal::is_terminal(&std::io::stdout()),
            t0,
            drawn: 0,
            last_draw: None,
            keys: Vec::new(),
        }
    }

    fn stamp(&self) -> String {
        format!("[{:7.2}s]", self.t0.elapsed().as_secs_f64())
    }

    /// Removes the block drawn last (terminal), so that text can go where it was.
    fn clear_block(&mut self, out: &mut impl Write) {
        if self.tty && self.drawn > 0 {
            let _ = write!(out, "\x1b[{}A\r\x1b[J", self.drawn);
            self.drawn = 0;
        }
    }

    /// Prints a message above the status lines, with the time since the start.
    pub fn message(&mut self, text: &str) {
        let mut out = std::io::stdout().lock();
        self.clear_block(&mut out);
        let _ = writeln!(out, "{} {text}", self.stamp());
        let _ = out.flush();
        // Redraw at the next update.
        self.last_draw = None;
    }

    /// Shows the processes' lines: on a terminal, redraws the block when a key changed or
    /// half a second has passed; otherwise prints each line whose key changed.
    pub fn update(&mut self, lines: &[Line]) {
        let mut out = std::io::stdout().lock();
        let changed =
            self.keys.len() != lines.len() || self.keys.iter().zip(lines).any(|(k, l)| *k != l.key);
        if self.tty {
            let due = self.last_draw.is_none_or(|t| t.elapsed() >= REDRAW);
            if !(changed || due) {
                return;
            }
            self.clear_block(&mut out);
            // Autowrap off while drawing: a line wider than the terminal is cut at its edge
            // rather than wrapped, so the block is exactly one row per process and the next
            // redraw moves up by the right count.
            let _ = write!(out, "\x1b[?7l");
            for l in lines {
                let _ = writeln!(out, "  {}", l.text);
            }
            let _ = write!(out, "\x1b[?7h");
            self.drawn = lines.len();
            self.last_draw = Some(Instant::now());
        } else {
            let stamp = self.stamp();
            for (i, l) in lines.iter().enumerate() {
                if self.keys.get(i) != Some(&l.key) {
                    let _ = writeln!(out, "{stamp} {}", l.text);
                }
            }
        }
        self.keys = lines.iter().map(|l| l.key.clone()).collect();
        let _ = out.flush();
    }

    /// Ends the live display: the block stays on screen as the last state, and what follows
    /// is printed below it.
    pub fn finish(&mut self) {
        self.drawn = 0;
    }
}
