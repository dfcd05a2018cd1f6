//! Operator actions from the page: events sent to the player as `petrel send` sends them, by a
//! thread of its own (iceoryx2 ports stay on the thread that opened them) that waits for the
//! player's verdict.

use petrel_ipc::{Participant, Role, Vehicle};
use petrel_value::Value;
use serde_json::{json, Value as Json};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;
use tokio::sync::oneshot;

/// How long the page waits for the player's verdict on an event.
const VERDICT_TIMEOUT: Duration = Duration::from_secs(5);

/// One event to send, and where its verdict goes.
pub struct Request {
    /// The event's name.
    pub name: String,
    /// Its parameters, checked against the project.
    pub params: Vec<Value>,
    /// The verdict: the player's answer as JSON, or why nothing could be sent.
    pub reply: oneshot::Sender<Result<Json, String>>,
}

/// A random token of 128 bits, in hexadecimal, from the system's generator.
pub fn new_token() -> Result<String, String> {
    use std::io::Read;
    let mut bytes = [0u8; 16];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut bytes))
        .map_err(|e| format!("cannot draw the operator token from /dev/urandom: {e}"))?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

/// The token written to a file only its owner may read (`--token-file`), removed when the
/// monitor ends.
pub struct TokenFile(PathBuf);

impl TokenFile {
    /// Writes `token` to `path`: a new file, owner-only (`0600`) from its creation, put in
    /// place by a rename (whatever was at `path`, a link included, is replaced, never
    /// followed or written through).
    pub fn write(path: &Path, token: &str) -> Result<TokenFile, String> {
        use std::io::Write;
        use std::os::unix::fs::OpenOptionsExt;
        let name = path
            .file_name()
            .ok_or_else(|| format!("--token-file {}: not the path of a file", path.display()))?;
        let tmp = path.with_file_name(format!(
            ".{}.{}.tmp",
            name.to_string_lossy(),
            std::process::id()
        ));
        let fail = |e: std::io::Error| {
            let _ = std::fs::remove_file(&tmp);
            format!("cannot write the operator token to {}: {e}", path.display())
        };
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o600)
            .open(&tmp)
            .map_err(|e| format!("cannot write the operator token to {}: {e}", path.display()))?;
        f.write_all(format!("{token}\n").as_bytes()).map_err(fail)?;
        drop(f);
        std::fs::rename(&tmp, path).map_err(fail)?;
        Ok(TokenFile(path.to_path_buf()))
    }
}

impl Drop for TokenFile {
    fn drop(&mut self) {
        // The token dies with the monitor: its file goes too.
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Compares two tokens in time independent of where they differ.
pub fn same_token(given: &str, token: &str) -> bool {
    given.len() == token.len()
        && given
            .bytes()
            .zip(token.bytes())
            .fold(0u8, |acc, (a, b)| acc | (a ^ b))
            == 0
}

/// Serves requests until the channel closes: joins `vehicle` as `tool/monitor-op<pid>`.
pub fn serve(vehicle: Vehicle, requests: mpsc::Receiver<Request>) {
    let joined = Role::tool(&format!("monitorop{}", std::process::id()))
        .map_err(|e| e.to_string())
        .and_then(|role| Participant::join(&vehicle, role).map_err(|e| e.to_string()))
        .and_then(|me| {
            let sender = me.event_sender_sized().map_err(|e| e.to_string())?;
            let beats = me.heartbeat_subscriber().map_err(|e| e.to_string())?;
            Ok((me, sender, beats))
        });
    let (_me, sender, beats) = match joined {
        Ok(j) => j,
        Err(e) => {
            for r in requests {
                let _ = r
                    .reply
                    .send(Err(format!("the monitor cannot send events: {e}")));
            }
            return;
        }
    };
    for r in requests {
        let msg = petrel_ipc::EventMsg::new(r.name.clone(), r.params);
        let verdict = match sender.send(&msg) {
            Ok(sent) => {
                let ack = petrel_ipc::wait_acknowledged(
                    &beats,
                    sender.sender_id(),
                    sent.seq,
                    VERDICT_TIMEOUT,
                );
                let refusal = ack
                    .ack
                    .as_ref()
                    .and_then(|a| a.refusals.iter().find(|f| f.seq == sent.seq))
                    .map(|f| f.reason.clone());
                let verdict = if let Some(reason) = &refusal {
                    format!("refused by the player: {reason}")
                } else if ack.settled(sent.seq) {
                    "taken and on record".to_string()
                } else if ack.ack.as_ref().is_some_and(|a| a.last_seq >= sent.seq) {
                    "taken, not yet on record".to_string()
                } else {
                    "not acknowledged by the player in time".to_string()
                };
                Ok(json!({
                    "event": r.name,
                    "origin": sender.origin().to_string(),
                    "seq": sent.seq,
                    "taken": refusal.is_none() && ack.ack.as_ref().is_some_and(|a| a.last_seq >= sent.seq),
                    "refused": refusal.is_some(),
                    "reason": refusal,
                    "verdict": verdict,
                }))
            }
            Err(petrel_ipc::SendError::NoReceiver { .. }) => Err(format!(
                "no player is running for vehicle `{}`",
                vehicle.name()
            )),
            Err(e) => Err(format!("cannot send: {e}")),
        };
        let _ = r.reply.send(verdict);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_compare_whole() {
        let t = new_token().unwrap();
        assert_eq!(t.len(), 32);
        assert!(same_token(&t, &t));
        assert!(!same_token(&t[..31], &t));
        assert!(!same_token("", &t));
        let mut other = t.clone().into_bytes();
        other[31] = if other[31] == b'0' { b'1' } else { b'0' };
        assert!(!same_token(std::str::from_utf8(&other).unwrap(), &t));
        assert_ne!(new_token().unwrap(), t);
    }

    #[test]
    fn the_token_file_is_owner_only_replaces_a_link_and_goes_at_the_end() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("monitor.token");
        let elsewhere = dir.path().join("elsewhere");
        std::fs::write(&elsewhere, "kept").unwrap();
        std::os::unix::fs::symlink(&elsewhere, &path).unwrap();
        let f = TokenFile::write(&path, "0123abcd").unwrap();
        let meta = std::fs::symlink_metadata(&path).unwrap();
        assert!(meta.is_file());
        assert_eq!(meta.permissions().mode() & 0o777, 0o600);
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "0123abcd\n");
        assert_eq!(std::fs::read_to_string(&elsewhere).unwrap(), "kept");
        drop(f);
        assert!(!path.exists());
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1, "{names:?}");
    }
}
