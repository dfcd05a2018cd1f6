//! PNML (ISO/IEC 15909-2) interchange: reading plain place/transition nets, and carrying whole
//! Petrel projects through PNML without loss.
//!
//! Three entry points:
//!
//! - [`parse_pnml`] reads any P/T-net PNML document (the Model Checking Contest models, for
//!   instance) into [`PtNet`]s: places, transitions and weighted arcs, nothing else (and
//!   whether a net is a Petrel export, [`PtNet::petrel_export`]).
//! - [`export_pnml`] writes a Petrel project as one P/T net, the project's **skeleton**: any
//!   PNML tool sees the structure of the nets the project runs and its initial state;
//!   everything else Petrel knows (manifest, parameters, instances, triggers, guards, emptiness
//!   tests, actions, comments, written order) travels in one `<toolspecific tool="petrel"
//!   version="2">` block, which other tools must keep and ignore.
//! - [`import_pnml`] reads such an export back into the identical
//!   [`Project`](crate::model::Project), or turns a plain P/T net into a project of immediate
//!   transitions, refusing (with a diagnostic per element) what Petrel's safe, unary nets cannot
//!   hold.
//!
//! The reader streams with `quick_xml` over the text (no DOM) so a megabyte of PNML reads in
//! milliseconds, and turns byte positions into [`Span`](petrel_diag::source::Span)s so every problem
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
//!   P/T net it annotates: a missing attribute, a name that is not a Petrel name, a guard, an
//!   action, arguments or an invariant that do not parse, copies that do not match the
//!   project's instances, an element, arc or marking of the P/T net that the data does not
//!   imply;
//! - `E0507` Petrel data of a version this Petrel does not read (it reads 1 and 2).
//!
//! # The P/T skeleton
//!
//! The page holds the nets the project **runs** ([`crate::instances`]): a plain net once, a
//! template once per instance (`R1`, `R2`), a child once per parent instance
//! (`MISSION/TRANSIT`). Ids are `NET.place` and `NET.transition` (`R1.moving`; the `/` of a
//! child instance is written `-`, as XML ids do not allow it: `MISSION-TRANSIT.cruising`),
//! `NET.CHILD.done` for a completion place and `global.NAME` for a global place; `<name>`
//! labels are the places' and transitions' names as Petrel writes them (`R1.moving`,
//! `MISSION/TRANSIT.cruising`). Arcs are what each transition's inputs and outputs say
//! (naming a place twice is an arc of weight 2). The initial marking is the mission's:
//! instances in `start` hold their places' tokens, global places theirs.
//!
//! What a P/T net cannot say is left out, so another tool's analysis is of a net that allows
//! more than the project does in each step, and knows nothing of activation:
//!
//! - an **emptiness test** (`not p`) has no arc: plain P/T PNML has no inhibitor arc, and the
//!   usual encoding (a complement place marked while `p` is empty) would have to follow every
//!   activation and deactivation, which the skeleton has not either; so a transition that
//!   tests `p` may fire in the skeleton when `p` is marked (an over-approximation);
//! - a **completion place** `CHILD.done` is a place of the parent's instance, and each
//!   `finish` of the child's instance is an output arc of its transition to it: the token the
//!   child hands its parent is in the skeleton (the deactivation that follows is not);
//! - **guards**, **events**, **timers**, **activation** and **deactivation** are not P/T
//!   notions: every transition may fire whenever its input places are marked, and the nets not
//!   in `start` start empty and stay so unless an arc marks them.
//!
//! `petrel verify FILE.pnml` says as much when it reads an export ([`SKELETON_NOTE`]).
//!
//! # The Petrel block
//!
//! One block at net level (inside `<net>`) holds the whole project; the elements of the page
//! carry none. Names are attributes; text of the net language (guards, actions, arguments,
//! invariants) is written as `petrel fmt` prints it and read back with the language's parser.
//!
//! ```xml
//! <toolspecific tool="petrel" version="2">
//!   <manifest name="ugv">
//!     <description>...</description>
//!     <file path="robot.pn"/>
//!     <start net="R1"/>
//!     <global name="ready" tokens="1" ref="global.ready"/>
//!     <global name="free" tokens="1" ref="global.free">   <!-- visible to some nets only -->
//!       <scope><net name="ROBOT"/><net name="SYNC"/></scope>
//!     </global>
//!     <instance name="R1" net="ROBOT" args="&quot;r1&quot;, 0.5"/>
//!     <invariant name="bottleneck">not (R1.inside and R2.inside)</invariant>
//!     <event name="alarm" category="safety"><param name="why" type="text"/></event>
//!     <event name="replan" category="mission" internal="true"/>  <!-- only the nets emit it -->
//!     <program name="PLN">
//!       <function name="goto"><param name="x" type="float"/><answer event="arrived"/></function>
//!     </program>
//!     <timer name="watchdog" event="timeout"/>
//!     <final><place name="MISSION.landed"/></final>
//!     <goal><place name="MISSION.loitering"/></goal>     <!-- [verify] goal -->
//!     <progress-excludes><category name="catastrophic"/></progress-excludes>  <!-- if written -->
//!   </manifest>
//!   <netfile path="robot.pn">
//!     <net name="ROBOT" blank-before="true">
//!       <comment>...</comment>
//!       <allow code="W0603" reason="..."/>             <!-- @allow before the net -->
//!       <param name="robot" type="text"/>              <!-- net ROBOT(robot: text) -->
//!       <place name="moving" tokens="1" marking-written="true">
//!         <comment>...</comment> <allow code="..."/> <trailing>...</trailing>
//!         <copy net="R1" ref="R1.moving"/>             <!-- its P/T place in each instance -->
//!         <copy net="R2" ref="R2.moving"/>
//!       </place>
//!       <children>                                    <!-- children TRANSIT(0.5), SURVEY -->
//!         <child net="TRANSIT" args="0.5"><copy net="R1" ref="R1.TRANSIT.done"/>...</child>
//!         <child net="SURVEY">...</child>             <!-- no `args`: written without () -->
//!       </children>
//!       <transition name="enter">
//!         <trigger event="at"><binding name="r"/><binding name="d" type="float"/></trigger>
//!         <guard>r == self.robot and d &gt; 1.0</guard>
//!         <input place="moving"/> <input place="TRANSIT.done"/>
//!         <empty place="busy"/>                        <!-- not busy -->
//!         <output place="waiting"/>
//!         <action><comment>...</comment><code>emit go to SYNC</code><trailing>...</trailing></action>
//!         <end-comment>...</end-comment>
//!         <copy net="R1" ref="R1.enter"/> <copy net="R2" ref="R2.enter"/>
//!       </transition>
//!       <end-comment>...</end-comment>
//!     </net>
//!     <end-comment>...</end-comment>
//!   </netfile>
//! </toolspecific>
//! ```
//!
//! Places, transitions and `children` lines stand in written order (the P/T net cannot record
//! it). A `<copy>` names, for one instance, the P/T node of an item; the copies of an item
//! follow the instances of its net in project order, and the import checks them against the
//! instances it expands from the data, then checks the whole P/T net (elements, arcs, initial
//! marking) against the skeleton the data implies: a document changed by another tool is
//! refused (`E0506`) rather than read wrong. Optional things are absent attributes or elements
//! (`args` of a child written without parentheses, `reason`, `<scope>`, `<guard>`), so `None`
//! and empty stay apart.
//!
//! **Version 1**, written before nets had parameters, is still read: the net block lists
//! `<item ref="NET.place"/>` in written order and each P/T element carries its own
//! `<toolspecific tool="petrel" version="1">` with its `<place>` or `<transition>` data. Its
//! projects are those without templates or children, whose nets are their own one instance.
//! An older Petrel refuses version 2 with a message instead of dropping what it cannot hold.
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

/// The version of the Petrel block that [`export_pnml`] writes; [`import_pnml`] reads it and
/// version 1.
pub const PETREL_VERSION: &str = "2";

/// What an analysis of a Petrel export's P/T net covers, for tools to say next to their
/// findings (`petrel verify FILE.pnml` does).
pub const SKELETON_NOTE: &str = "this file is a Petrel export: only its P/T skeleton is analysed (no events, no activation or deactivation, no emptiness tests, no guards: every transition may fire whenever its input places are marked), so its dead markings and unsafe places are the skeleton's, not the mission's; import it (`petrel import`) and run `petrel verify DIR` for the project's analysis";

/// The PNML type of P/T nets, written on export.
pub const PTNET_TYPE: &str = "http://www.pnml.org/version-2009/grammar/ptnet";

/// The PNML namespace, written on export.
pub const PNML_NAMESPACE: &str = "http://www.pnml.org/version-2009/grammar/pnml";
