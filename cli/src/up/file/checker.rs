//! The vehicle file's checker: its findings (E08xx) at their place, and the checks that
//! several tables share (durations, templates, computers, timed sends) and the `[link]`
//! table's.

use super::raw::{RawLink, RawSend};
use super::{expand, suggest, Computer, Kind, LinkSpec, SendSpec};
use petrel_diag::report::{Diagnostic, Diagnostics};
use petrel_diag::source::{FileId, Span};
use petrel_nets::compiled::CompiledProject;
use std::time::Duration;
use toml::Spanned;

/// Reports a vehicle file's findings (E08xx) at their place, counting the errors.
pub(super) struct VehicleChecker<'a> {
    /// The file checked.
    pub(super) file: FileId,
    /// Where the findings go.
    pub(super) diags: &'a mut Diagnostics,
    /// Errors so far (warnings apart).
    pub(super) errors: usize,
    /// The project, when it checks clean: programs and events are checked against it.
    pub(super) project: Option<&'a CompiledProject>,
}

impl<'a> VehicleChecker<'a> {
    /// A checker of `file`, none found yet.
    pub(super) fn new(
        file: FileId,
        diags: &'a mut Diagnostics,
        project: Option<&'a CompiledProject>,
    ) -> Self {
        VehicleChecker {
            file,
            diags,
            errors: 0,
            project,
        }
    }

    /// The `[link]` table: its events must be the project's, of the communication category,
    /// with one `text` parameter (the computer's name).
    pub(super) fn link(&mut self, l: &RawLink, computers: &[Computer]) -> LinkSpec {
        if computers.is_empty() {
            let span = self.first_span(&[l.detection.as_ref(), l.lost_event.as_ref()]);
            self.error(
                "E0812",
                span,
                "a [link] table but no [computers]".into(),
                "nothing to link",
                "declare the computers ([computers.NAME] with `gateway = \"tcp/ADDRESS:PORT\"`), or remove [link]",
            );
        }
        let detection = l
            .detection
            .as_ref()
            .and_then(|d| self.duration(d, "[link] detection"));
        let retention = l
            .retention
            .as_ref()
            .and_then(|r| self.retention(r, detection));
        let lost_event = self.link_event(&l.lost_event, "lost_event");
        let restored_event = self.link_event(&l.restored_event, "restored_event");
        self.credentials(l);
        let insecure = l.security.as_ref().is_some_and(|s| self.security(s));
        LinkSpec {
            detection,
            retention,
            lost_event,
            restored_event,
            user: l.user.as_ref().map(|u| u.get_ref().clone()),
            credentials: l.credentials.as_ref().map(|u| u.get_ref().clone()),
            insecure,
        }
    }

    /// `[link] retention`: longer than the detection bound (`detection`, or its default).
    fn retention(&mut self, r: &Spanned<String>, detection: Option<Duration>) -> Option<Duration> {
        let retention = self.duration(r, "[link] retention")?;
        let bound = detection.unwrap_or(crate::gateway::DEFAULT_DETECTION);
        if retention <= bound {
            self.error(
                "E0812",
                self.span(r),
                format!(
                    "[link] retention ({}) must be longer than the detection bound ({:?})",
                    r.get_ref(),
                    bound
                ),
                "not longer than detection",
                "a carried message is sent again while it is younger than retention - detection: give retention several detection bounds (default 30s)",
            );
            return None;
        }
        Some(retention)
    }

    /// `[link] lost_event` or `restored_event` (`what`): the project's, of the communication
    /// category, with one `text` parameter (the computer's name).
    fn link_event(&mut self, e: &Option<Spanned<String>>, what: &str) -> Option<String> {
        let e = e.as_ref()?;
        let name = e.get_ref();
        if let Some(project) = self.project {
            let found = project.events.iter().find(|ev| &ev.name == name);
            let link = |ev: &&petrel_nets::compiled::Event| {
                ev.category == petrel_nets::model::Category::Communication
                    && ev.params.len() == 1
                    && ev.params[0].1 == petrel_nets::model::Type::Text
            };
            if !found.is_some_and(|ev| link(&ev)) {
                let why = match found {
                    None => {
                        // The hint is among the events that could be link events.
                        let hint = petrel_diag::names::suggest(
                            name,
                            project.events.iter().filter(link).map(|e| e.name.as_str()),
                            petrel_diag::names::Candidates::Declared,
                        );
                        format!("`{name}` is not an event of the project: {hint}")
                    }
                    Some(_) => format!(
                        "`{name}` is not of category communication with one `text` parameter"
                    ),
                };
                self.error(
                    "E0812",
                    self.span(e),
                    format!("[link] {what}: {why}"),
                    "not a link event",
                    &format!("declare it in petrel.toml: {name} = {{ category = \"communication\", params = [\"computer: text\"] }}"),
                );
                return None;
            }
        }
        Some(name.clone())
    }

    /// `[link] user` and `credentials`: both or neither; the credentials inside the project.
    fn credentials(&mut self, l: &RawLink) {
        if l.user.is_some() != l.credentials.is_some() {
            let span = self.first_span(&[l.user.as_ref(), l.credentials.as_ref()]);
            self.error(
                "E0812",
                span,
                "[link] `user` and `credentials` go together".into(),
                "only one of them",
                "give both: `user`, the gateways' zenoh user, and `credentials`, the file of `user:password` lines they accept",
            );
        }
        if let Some(cred) = &l.credentials {
            if let Err(e) = petrel_diag::paths::check_relative(cred.get_ref()) {
                self.error(
                    "E0812",
                    self.span(cred),
                    format!("[link] credentials: {e}"),
                    "not a path inside the project",
                    "give a path relative to the project directory",
                );
            }
        }
    }

    /// `[link] security`: "tls" (the default) or "none", a lab bench's opt-out, which is
    /// warned of. True for "none".
    fn security(&mut self, s: &Spanned<String>) -> bool {
        match s.get_ref().as_str() {
            "tls" => false,
            "none" => {
                self.diags.push(
                    Diagnostic::warning(
                        "W0802",
                        self.span(s),
                        petrel_gateway::session::INSECURE_WARNING.to_string(),
                    )
                    .label("the link is open")
                    .help("remove `security = \"none\"`: the gateways then use mutual TLS with the vehicle's keys (docs/gateway.md)"),
                );
                true
            }
            other => {
                self.error(
                    "E0812",
                    self.span(s),
                    format!("[link] security `{other}` is not \"tls\" or \"none\""),
                    "not a security",
                    "leave it out (mutual TLS, the default), or write \"none\" for a lab bench whose link needs no protection",
                );
                false
            }
        }
    }

    /// Where `s` is in the file.
    pub(super) fn span<T>(&self, s: &Spanned<T>) -> Span {
        Span::new(self.file, s.span().start, s.span().end)
    }

    /// Where the first given of these optional fields is; the file's start if none is.
    pub(super) fn first_span<T>(&self, fields: &[Option<&Spanned<T>>]) -> Span {
        fields
            .iter()
            .flatten()
            .next()
            .map(|s| self.span(s))
            .unwrap_or(Span::new(self.file, 0, 0))
    }

    /// An error: `message` at `span`, with its label and help.
    pub(super) fn error(
        &mut self,
        code: &'static str,
        span: Span,
        message: String,
        label: &str,
        help: &str,
    ) {
        self.errors += 1;
        self.diags.push(
            Diagnostic::error(code, span, message)
                .label(label)
                .help(help),
        );
    }

    /// A duration (`500ms`, `2s`), or E0806.
    pub(super) fn duration(&mut self, d: &Spanned<String>, what: &str) -> Option<Duration> {
        match petrel_diag::duration::parse_duration_us(d.get_ref()) {
            Some(us) => Some(Duration::from_micros(us)),
            None => {
                self.error(
                    "E0806",
                    self.span(d),
                    format!("`{}` is not a duration ({what})", d.get_ref()),
                    "not a duration",
                    "write a number and a unit: `500ms`, `2s`, `1.5s`, `1min`",
                );
                None
            }
        }
    }

    /// A template whose substitutions are among `vars`, or E0808.
    pub(super) fn template(&mut self, t: &Spanned<String>, vars: &[&str], what: &str) {
        if let Err(e) = expand(t.get_ref(), &|n| vars.contains(&n).then(String::new)) {
            let list: Vec<String> = vars.iter().map(|v| format!("{{{v}}}")).collect();
            self.error(
                "E0808",
                self.span(t),
                format!("{e} in {what}"),
                "bad substitution",
                &format!("{what} may use {}", list.join(", ")),
            );
        }
    }

    /// A field that a process of this kind does not take (E0805).
    pub(super) fn not_for_kind(
        &mut self,
        span: Span,
        field: &str,
        process: &str,
        kind: Kind,
        help: &str,
    ) {
        self.error(
            "E0805",
            span,
            format!(
                "`{field}` does not apply to process `{process}` (kind {})",
                kind.as_str()
            ),
            "not for this kind",
            help,
        );
    }

    /// An operator event, read as a script line holds it.
    pub(super) fn send(&mut self, raw: &RawSend) -> Option<SendSpec> {
        let at = self.duration(&raw.at, "`at` of a [[send]]");
        let text = raw.event.get_ref().trim().to_string();
        let event = match self.project {
            // Without a project that checks, the event cannot be read: the project's own
            // errors are reported instead.
            None => None,
            Some(c) => match crate::common::operator_event(&text, c) {
                Ok(e) => Some(e),
                Err(e) => {
                    self.error(
                        "E0809",
                        self.span(&raw.event),
                        format!("the event `{text}` cannot be sent: {e}"),
                        "not an event of the project",
                        "write an event of the manifest's [events] as in a script: `start_mission` or `payload_failure(\"camera\")`",
                    );
                    None
                }
            },
        };
        let (name, params) = event?;
        Some(SendSpec {
            at: at?,
            text,
            name,
            params,
            computer: raw.computer.as_ref().map(|c| c.get_ref().clone()),
        })
    }

    /// A computer the file declares, or E0804.
    pub(super) fn computer_ref(&mut self, c: &Spanned<String>, computers: &[Computer], what: &str) {
        if computers.iter().any(|k| &k.name == c.get_ref()) {
            return;
        }
        let help = if computers.is_empty() {
            format!("declare it in a [computers.{}] table (with its address), or remove `computer`: without [computers] the vehicle is one computer", c.get_ref())
        } else {
            format!(
                "{}the computers are {}",
                suggest(c.get_ref(), computers.iter().map(|k| k.name.as_str())),
                computers
                    .iter()
                    .map(|k| format!("`{}`", k.name))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        };
        self.error(
            "E0804",
            self.span(c),
            format!("{what} names an unknown computer `{}`", c.get_ref()),
            "no such computer",
            &help,
        );
    }
}
