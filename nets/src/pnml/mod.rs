//! PNML (ISO/IEC 15909-2) interchange: reading plain place/transition nets, and carrying whole
//! Petrel projects through PNML without loss.
//!
//! Three entry points:
//!
//! - [`parse_pnml`] reads any P/T-net PNML document (the Model Checking Contest models, for
//!   instance) into [`PtNet`]s: places, transitions and weighted arcs, nothing else.
//! - [`export_pnml`] writes a Petrel project as one P/T net. Any PNML tool sees the project's
//!   structure and initial state; everything else Petrel knows (manifest, triggers, actions,
//!   comments, written order) travels in `<toolspecific tool="petrel" version="1">` blocks, which
//!   other tools must keep and ignore.
//! - [`import_pnml`] reads such an export back into the identical
//!   [`Project`](crate::model::Project), or turns a plain P/T net into a project of immediate
//!   transitions, refusing (with a diagnostic per element) what Petrel's safe, unary nets cannot
//!   hold.
//!
//! The reader streams with `quick_xml` over the text (no DOM) so a megabyte of PNML reads in
//! milliseconds, and turns byte positions into [`Span`](crate::source::Span)s so every problem
//! shows `file:line:col`.
//!
//! Diagnostic codes:
//!
//! - `E0501` malformed PNML (XML syntax, unclosed element, missing id, bad number...);
//! - `E0502` an arc whose source or target is unknown, or that joins two places or two
//!   transitions;
//! - `E0503` a net that is not a P/T net (colored, symmetric, high-level...);
//! - `E0504` an arc weight above 1, which Petrel nets cannot express;
//! - `E0505` an initial marking above 1, which Petrel places cannot hold;
//! - `E0506` Petrel data (`<toolspecific tool="petrel">`) that is invalid or disagrees with the
//!   P/T net it annotates.
//!
//! # The Petrel blocks
//!
//! At net level (inside `<net>`), one block holds the manifest and the layout of the net files:
//!
//! ```xml
//! <toolspecific tool="petrel" version="1">
//!   <manifest name="uav">
//!     <description>...</description>
//!     <file path="nav.pn"/>
//!     <start net="nav"/>
//!     <global name="ready" tokens="1" ref="global.ready"/>
//!     <event name="alarm" category="safety"><param name="why" type="text"/></event>
//!     <program name="PLN"><function name="goto"><param name="x" type="float"/></function></program>
//!     <timer name="watchdog" event="timeout"/>
//!   </manifest>
//!   <netfile path="nav.pn">
//!     <net name="nav" blank-before="true">
//!       <comment>...</comment>
//!       <item ref="nav.idle"/>
//!       <item ref="nav.go"/>
//!       <end-comment>...</end-comment>
//!     </net>
//!     <end-comment>...</end-comment>
//!   </netfile>
//! </toolspecific>
//! ```
//!
//! Each `<place>` and `<transition>` of the page carries its own block (`<place name tokens
//! marking-written blank-before>` or `<transition name blank-before>` with comments, trailing
//! comment, trigger, inputs, outputs, actions and end comments). `<item ref>` fixes the written
//! order of places and transitions, which the P/T net alone cannot record.
//!
//! One private module per job, so that each can be read alone: `xml` (the streaming reader and
//! escaping), `read` (a document into [`PtNet`]s), `export` and `import` (whole projects), and
//! `view` (the P/T ids that export and import both give a project's places and transitions).
//! The P/T net type is [`crate::pt`], re-exported here: the explorer uses it without PNML.

mod export;
mod import;
mod read;
mod view;
mod xml;

pub use crate::pt::{PtArc, PtNet, PtNode, PtPlace, PtTransition};
pub use export::export_pnml;
pub use import::import_pnml;
pub use read::parse_pnml;

/// The PNML type of P/T nets, written on export.
pub const PTNET_TYPE: &str = "http://www.pnml.org/version-2009/grammar/ptnet";

/// The PNML namespace, written on export.
pub const PNML_NAMESPACE: &str = "http://www.pnml.org/version-2009/grammar/pnml";
