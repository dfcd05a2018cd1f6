//! The Redermor AUV's domain, sans-I/O: the mission file, planning (PLN), the simulated vehicle
//! and its sensors, the dynamic data manager (GDD), guidance (GUI), the pilot (IDC), the event
//! listener (EVT) and the plots of a run, in the manner of section 3.1 of the ProCoSA paper.
//!
//! Plain data in, data out: no bus, no process, no thread, and the clock is an argument (seconds
//! as `f64` for the dynamics, microseconds as `u64` for timestamps). The processes that carry
//! these programs on the CAN bus and the player are built elsewhere on top of this crate.
//!
//! ```text
//!  mission.toml --Mission::from_toml--> Mission --Planner--> MissionPlan (stages of legs)
//!                                                               |
//!   sim::Simulator (vehicle + sensors + scenario)               v
//!     --Samples--> gdd::Gdd --NavState--> guidance::Guidance --Setpoint--> pilot::Pilot
//!     ^                                                                      |
//!     +------------------------- vehicle::Commands <-------------------------+
//!  sim::MissionRun ties them up in one loop and records a plot::Trace for plot::map_svg.
//! ```
//!
//! The local frame is metric: `x` east, `y` north, in metres; headings are nautical, in
//! radians, 0 north and clockwise positive (90° is east), as a compass reads.
//!
//! - [`mission`]: the mission file (TOML), its validation with errors naming the field.
//! - [`plan`]: PLN: itinerary, obstacle-avoiding paths, lawnmower surveys, replans.
//! - [`vehicle`]: the vehicle's dynamics (two thrusters, a depth loop, current, battery, faults).
//! - [`sensors`]: sensors at their real rates, and the fault scenario (TOML).
//! - [`sim`]: the Redermor simulator, and the closed loop of a whole mission.
//! - [`gdd`]: GDD: the vehicle's state from sensor readings (dead reckoning, current).
//! - [`guidance`]: GUI: line-of-sight leg following, arrivals and course changes.
//! - [`pilot`]: IDC: heading, speed and depth controllers giving thruster commands.
//! - [`evt`]: EVT: operator requests and payload detections into mission events.
//! - [`plot`]: the SVG map of Figure 9 and a depth/time plot.
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod evt;
pub mod gdd;
pub mod geom;
pub mod guidance;
pub mod mission;
pub mod pilot;
pub mod plan;
pub mod plot;
pub mod sensors;
pub mod sim;
pub mod vehicle;

/// The geometry crate of the public API (positions are [`geo::Coord`], areas [`geo::Polygon`]).
pub use geo;
