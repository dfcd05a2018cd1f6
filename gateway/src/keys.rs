//! The vehicle's keys: a certificate authority of its own (the vehicle CA) and, for each of its
//! computers, a private key and a certificate whose common name is the computer's name, signed
//! by that CA. The gateways open their zenoh sessions with them in mutual TLS, and accept from
//! each peer only what its certificate's name allows it to say ([`crate::session`]).
//!
//! A keys directory holds `ca.pem` (the CA's certificate), optionally `ca.key` (its private
//! key: needed only to make certificates, keep it off the vehicle), and `NAME.pem` / `NAME.key`
//! for some of the computers (a computer needs its own and `ca.pem`). Every file is the user's
//! own, mode `0600`, in a directory `0700`; a private key others may read is refused.
//!
//! By default a vehicle's keys are in this user's state directory, `keys/<vehicle>/` under
//! [`state_dir`]. docs/gateway.md says how they are made and reach each computer.

use std::fs::{self, File, OpenOptions};
use std::io::{Read, Write};
use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};

use rcgen::{
    BasicConstraints, CertificateParams, DistinguishedName, DnType, ExtendedKeyUsagePurpose, IsCa,
    Issuer, KeyPair, KeyUsagePurpose,
};

/// Overrides this user's state directory (where the vehicles' keys are kept by default).
pub const STATE_DIR_ENV: &str = "PETREL_STATE_DIR";

/// The CA's certificate in a keys directory.
pub const CA_CERT: &str = "ca.pem";
/// The CA's private key in a keys directory.
pub const CA_KEY: &str = "ca.key";

/// Why keys could not be read or made.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum KeyError {
    /// Files a computer needs are not in the directory.
    Missing {
        /// The keys directory.
        dir: PathBuf,
        /// The files missing there.
        files: Vec<String>,
    },
    /// A file or directory others could read or change, a link, or one of another user.
    Unsafe(String),
    /// Anything else: an I/O error, a file that does not parse, no home directory.
    Other(String),
}

impl std::fmt::Display for KeyError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            KeyError::Missing { dir, files } => {
                write!(f, "{} has no {}", dir.display(), files.join(", "))
            }
            KeyError::Unsafe(why) | KeyError::Other(why) => f.write_str(why),
        }
    }
}

impl std::error::Error for KeyError {}

fn io(path: &Path, what: &str, e: std::io::Error) -> KeyError {
    KeyError::Other(format!("{what} {}: {e}", path.display()))
}

/// One computer's keys, read and checked: what its gateway opens its session with (PEM texts).
#[derive(Clone, PartialEq, Eq)]
pub struct ComputerKeys {
    /// The directory they were read from.
    pub dir: PathBuf,
    /// The vehicle CA's certificate.
    pub ca: String,
    /// The computer's certificate.
    pub certificate: String,
    /// The computer's private key.
    pub key: String,
}

impl std::fmt::Debug for ComputerKeys {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never the private key in a log.
        f.debug_struct("ComputerKeys")
            .field("dir", &self.dir)
            .finish_non_exhaustive()
    }
}

/// This user's state directory for Petrel: `$PETREL_STATE_DIR`, else `$XDG_STATE_HOME/petrel`,
/// else `$HOME/.local/state/petrel`.
pub fn state_dir() -> Result<PathBuf, KeyError> {
    let var = |name: &str| std::env::var_os(name).filter(|v| !v.is_empty());
    if let Some(d) = var(STATE_DIR_ENV) {
        return Ok(PathBuf::from(d));
    }
    if let Some(d) = var("XDG_STATE_HOME") {
        return Ok(PathBuf::from(d).join("petrel"));
    }
    match var("HOME") {
        Some(h) => Ok(PathBuf::from(h).join(".local/state/petrel")),
        None => Err(KeyError::Other(format!(
            "no state directory: set {STATE_DIR_ENV} (or HOME)"
        ))),
    }
}

/// Where a vehicle's keys are by default: `keys/<vehicle>` in [`state_dir`].
pub fn default_dir(vehicle: &str) -> Result<PathBuf, KeyError> {
    Ok(state_dir()?.join("keys").join(vehicle))
}

/// The effective user id of this process (the owner of `/proc/self`), without `unsafe`.
fn my_uid() -> Result<u32, KeyError> {
    fs::metadata("/proc/self")
        .map(|m| m.uid())
        .map_err(|e| io(Path::new("/proc/self"), "cannot read", e))
}

/// Checks that `m` (of `path`) is this user's and that nobody else may use it at all.
fn owner_only(path: &Path, m: &fs::Metadata, uid: u32) -> Result<(), KeyError> {
    if m.file_type().is_symlink() {
        return Err(KeyError::Unsafe(format!(
            "{} is a symbolic link: keys are never read through one",
            path.display()
        )));
    }
    if m.uid() != uid {
        return Err(KeyError::Unsafe(format!(
            "{} belongs to user {}, not to this one ({uid})",
            path.display(),
            m.uid()
        )));
    }
    let mode = m.permissions().mode() & 0o777;
    if mode & 0o077 != 0 {
        return Err(KeyError::Unsafe(format!(
            "{} is open to others (mode {mode:04o}): `chmod {} {}`",
            path.display(),
            if m.is_dir() { "700" } else { "600" },
            path.display()
        )));
    }
    Ok(())
}

/// Reads a file of the keys directory, checked owner-only.
fn read_private(path: &Path, uid: u32) -> Result<String, KeyError> {
    let link = fs::symlink_metadata(path).map_err(|e| io(path, "cannot read", e))?;
    owner_only(path, &link, uid)?;
    let mut file = File::open(path).map_err(|e| io(path, "cannot open", e))?;
    // The file opened is the one checked (not replaced in between).
    let opened = file.metadata().map_err(|e| io(path, "cannot read", e))?;
    if (opened.dev(), opened.ino()) != (link.dev(), link.ino()) || !opened.is_file() {
        return Err(KeyError::Unsafe(format!(
            "{} changed while it was read",
            path.display()
        )));
    }
    let mut text = String::new();
    file.read_to_string(&mut text)
        .map_err(|e| io(path, "cannot read", e))?;
    Ok(text)
}

/// The files `computer` needs in a keys directory.
fn needed(computer: &str) -> [String; 3] {
    [
        CA_CERT.to_owned(),
        format!("{computer}.pem"),
        format!("{computer}.key"),
    ]
}

/// Reads `computer`'s keys from `dir`, refusing any file or directory others may use.
pub fn load(dir: &Path, computer: &str) -> Result<ComputerKeys, KeyError> {
    let uid = my_uid()?;
    let missing: Vec<String> = needed(computer)
        .into_iter()
        .filter(|f| fs::symlink_metadata(dir.join(f)).is_err())
        .collect();
    if !missing.is_empty() {
        return Err(KeyError::Missing {
            dir: dir.to_path_buf(),
            files: missing,
        });
    }
    let m = fs::symlink_metadata(dir).map_err(|e| io(dir, "cannot read", e))?;
    owner_only(dir, &m, uid)?;
    let [ca, certificate, key] = needed(computer).map(|f| read_private(&dir.join(f), uid));
    let keys = ComputerKeys {
        dir: dir.to_path_buf(),
        ca: ca?,
        certificate: certificate?,
        key: key?,
    };
    KeyPair::from_pem(&keys.key)
        .map_err(|e| KeyError::Other(format!("{}/{computer}.key: {e}", dir.display())))?;
    Ok(keys)
}

/// The computers among `computers` whose certificate and key are in `dir` (with the CA's).
pub fn present(dir: &Path, computers: &[String]) -> Vec<String> {
    computers
        .iter()
        .filter(|c| needed(c).iter().all(|f| dir.join(f).is_file()))
        .cloned()
        .collect()
}

/// Makes `dir` (and its missing parents) owner-only, or checks the one that exists.
fn private_dir(dir: &Path, uid: u32) -> Result<(), KeyError> {
    fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(dir)
        .map_err(|e| io(dir, "cannot create", e))?;
    let m = fs::symlink_metadata(dir).map_err(|e| io(dir, "cannot read", e))?;
    owner_only(dir, &m, uid)
}

/// Writes a new owner-only file (never over an existing one, nor through a link).
fn write_private(path: &Path, text: &str) -> Result<(), KeyError> {
    let mut f = OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(path)
        .map_err(|e| io(path, "cannot create", e))?;
    f.write_all(text.as_bytes())
        .and_then(|()| f.sync_all())
        .map_err(|e| io(path, "cannot write", e))
}

fn rc(what: &str, e: rcgen::Error) -> KeyError {
    KeyError::Other(format!("cannot make {what}: {e}"))
}

/// The CA's certificate: `petrel vehicle <vehicle>`, for signing certificates only. Like the
/// computers' certificates, it has rcgen's validity (1975 to 4096): a vehicle's clock may be
/// anything at boot, and a key is withdrawn by making new keys, not by waiting.
fn ca_params(vehicle: &str) -> Result<CertificateParams, KeyError> {
    let mut p = CertificateParams::new(Vec::<String>::new()).map_err(|e| rc("the CA", e))?;
    let mut dn = DistinguishedName::new();
    dn.push(DnType::CommonName, format!("petrel vehicle {vehicle}"));
    p.distinguished_name = dn;
    p.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    p.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    Ok(p)
}

/// A computer's certificate: common name (and DNS name) the computer's name, for both ends of
/// a TLS link. A computer name has no dot, so no public authority can certify it.
fn computer_params(computer: &str) -> Result<CertificateParams, KeyError> {
    let mut p = CertificateParams::new(vec![computer.to_owned()])
        .map_err(|e| rc(&format!("the certificate of `{computer}`"), e))?;
    let mut dn = DistinguishedName::new();
    dn.push(DnType::CommonName, computer);
    p.distinguished_name = dn;
    p.is_ca = IsCa::ExplicitNoCa;
    p.key_usages = vec![KeyUsagePurpose::DigitalSignature];
    p.extended_key_usages = vec![
        ExtendedKeyUsagePurpose::ServerAuth,
        ExtendedKeyUsagePurpose::ClientAuth,
    ];
    p.use_authority_key_identifier_extension = true;
    Ok(p)
}

/// Makes the keys of `vehicle` in `dir`, or completes them: the CA if the directory has none,
/// then a key and certificate for each of `computers` that has none there (an existing one is
/// never replaced). Returns the files made. Several processes may call it at once (the
/// gateways of a vehicle started together): they take turns on a lock in the directory.
pub fn make(dir: &Path, vehicle: &str, computers: &[String]) -> Result<Vec<String>, KeyError> {
    let uid = my_uid()?;
    private_dir(dir, uid)?;
    let lock_path = dir.join(".lock");
    let lock = OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(false)
        .mode(0o600)
        .open(&lock_path)
        .map_err(|e| io(&lock_path, "cannot open", e))?;
    lock.lock().map_err(|e| io(&lock_path, "cannot lock", e))?;
    let mut made = Vec::new();
    let ca_cert = dir.join(CA_CERT);
    let ca_key = dir.join(CA_KEY);
    if fs::symlink_metadata(&ca_cert).is_err() {
        let key = KeyPair::generate().map_err(|e| rc("the CA's key", e))?;
        let cert = ca_params(vehicle)?
            .self_signed(&key)
            .map_err(|e| rc("the CA", e))?;
        // The key first: a CA certificate alone is taken as "the CA key is elsewhere".
        write_private(&ca_key, &key.serialize_pem())?;
        write_private(&ca_cert, &cert.pem())?;
        made.extend([CA_KEY.to_owned(), CA_CERT.to_owned()]);
    }
    let wanted: Vec<&String> = computers
        .iter()
        .filter(|c| fs::symlink_metadata(dir.join(format!("{c}.pem"))).is_err())
        .collect();
    if wanted.is_empty() {
        return Ok(made);
    }
    if fs::symlink_metadata(&ca_key).is_err() {
        return Err(KeyError::Missing {
            dir: dir.to_path_buf(),
            files: vec![format!(
                "{CA_KEY} (the vehicle CA's key, to certify {})",
                wanted
                    .iter()
                    .map(|c| c.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )],
        });
    }
    let issuer_key = KeyPair::from_pem(&read_private(&ca_key, uid)?)
        .map_err(|e| KeyError::Other(format!("{}: {e}", ca_key.display())))?;
    let issuer = Issuer::from_ca_cert_pem(&read_private(&ca_cert, uid)?, issuer_key)
        .map_err(|e| KeyError::Other(format!("{}: {e}", ca_cert.display())))?;
    for computer in wanted {
        let key = KeyPair::generate().map_err(|e| rc("a computer's key", e))?;
        let cert = computer_params(computer)?
            .signed_by(&key, &issuer)
            .map_err(|e| rc(&format!("the certificate of `{computer}`"), e))?;
        // A key left without its certificate (a crash in between) is replaced next time.
        let key_path = dir.join(format!("{computer}.key"));
        let _ = fs::remove_file(&key_path);
        write_private(&key_path, &key.serialize_pem())?;
        write_private(&dir.join(format!("{computer}.pem")), &cert.pem())?;
        made.extend([format!("{computer}.key"), format!("{computer}.pem")]);
    }
    Ok(made)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn made_keys_load_and_are_owner_only() {
        let t = tempfile::tempdir().unwrap();
        let dir = t.path().join("keys/v1");
        let names = vec!["A".to_string(), "B".to_string()];
        let made = make(&dir, "v1", &names).unwrap();
        assert_eq!(made.len(), 6, "{made:?}");
        assert_eq!(
            fs::metadata(&dir).unwrap().permissions().mode() & 0o777,
            0o700
        );
        for f in &made {
            let mode = fs::metadata(dir.join(f)).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode, 0o600, "{f}");
        }
        let a = load(&dir, "A").unwrap();
        assert!(a.certificate.contains("BEGIN CERTIFICATE"));
        assert!(!format!("{a:?}").contains("PRIVATE"), "no key in Debug");
        // Made again: nothing new; a new computer gets its certificate from the same CA.
        assert!(make(&dir, "v1", &names).unwrap().is_empty());
        let more = make(&dir, "v1", &["C".to_string()]).unwrap();
        assert_eq!(more, vec!["C.key", "C.pem"]);
        assert_eq!(load(&dir, "C").unwrap().ca, a.ca);
        assert_eq!(present(&dir, &["A".into(), "Z".into()]), vec!["A"]);
    }

    #[test]
    fn missing_and_open_keys_are_refused_with_the_reason() {
        let t = tempfile::tempdir().unwrap();
        let dir = t.path().join("k");
        make(&dir, "v1", &["A".to_string()]).unwrap();
        match load(&dir, "B") {
            Err(KeyError::Missing { files, .. }) => assert_eq!(files, vec!["B.pem", "B.key"]),
            other => panic!("{other:?}"),
        }
        fs::set_permissions(dir.join("A.key"), fs::Permissions::from_mode(0o644)).unwrap();
        let e = load(&dir, "A").unwrap_err();
        assert!(
            matches!(&e, KeyError::Unsafe(w) if w.contains("chmod 600")),
            "{e}"
        );
        fs::set_permissions(dir.join("A.key"), fs::Permissions::from_mode(0o600)).unwrap();
        // Without the CA's key, no new certificate: it says which file is missing.
        fs::remove_file(dir.join(CA_KEY)).unwrap();
        let e = make(&dir, "v1", &["B".to_string()]).unwrap_err();
        assert!(e.to_string().contains("ca.key"), "{e}");
        assert!(load(&dir, "A").is_ok());
    }
}
