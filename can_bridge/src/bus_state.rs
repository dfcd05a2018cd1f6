//! The state of a CAN controller, as error frames and the interface tell it.
//!
//! A CAN controller is **error-active** while its error counters are low, gives **warnings**
//! from 96 errors, turns **error-passive** from 128 (it may no longer signal errors actively)
//! and goes **bus-off** from 256 (it no longer takes part in the bus until restarted). SocketCAN
//! reports these changes as error frames (controller class, bus-off class, restarted class) and
//! through netlink (the interface's state). Below everything that names a state (the buses,
//! `can.toml`, events), so that none of them has to import another for it.

use std::fmt;

use crate::frame::{err, Frame};

/// The state of a CAN controller.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum BusState {
    /// Fewer than 96 errors: normal.
    ErrorActive,
    /// 96 errors or more.
    ErrorWarning,
    /// 128 errors or more: the controller no longer signals errors actively.
    ErrorPassive,
    /// 256 errors or more: the controller is off the bus until restarted.
    BusOff,
    /// The interface is stopped (down).
    Stopped,
    /// The controller sleeps.
    Sleeping,
}

impl BusState {
    /// Every state, in the order above.
    pub const ALL: [BusState; 6] = [
        BusState::ErrorActive,
        BusState::ErrorWarning,
        BusState::ErrorPassive,
        BusState::BusOff,
        BusState::Stopped,
        BusState::Sleeping,
    ];

    /// The state's name in `can.toml` and in event parameters: `error_active`,
    /// `error_warning`, `error_passive`, `bus_off`, `stopped`, `sleeping`.
    pub fn name(self) -> &'static str {
        match self {
            BusState::ErrorActive => "error_active",
            BusState::ErrorWarning => "error_warning",
            BusState::ErrorPassive => "error_passive",
            BusState::BusOff => "bus_off",
            BusState::Stopped => "stopped",
            BusState::Sleeping => "sleeping",
        }
    }

    /// The state named `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    /// True for the states in which frames go through (active, warning, passive).
    pub fn is_on_bus(self) -> bool {
        matches!(
            self,
            BusState::ErrorActive | BusState::ErrorWarning | BusState::ErrorPassive
        )
    }
}

impl fmt::Display for BusState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The state an error frame reports, if it reports one: bus-off, a restart (back to
/// error-active), or a controller problem (error-passive, warning, back to active); failing
/// those, the error counters when the frame carries them. Protocol errors, missing
/// acknowledgements and lost arbitrations change no state (they are counted).
pub fn state_from_error_frame(frame: &Frame) -> Option<BusState> {
    if !frame.is_error() {
        return None;
    }
    let class = frame.error_class();
    let data = frame.payload();
    let byte = |i: usize| data.get(i).copied().unwrap_or(0);
    if class & err::BUSOFF != 0 {
        return Some(BusState::BusOff);
    }
    if class & err::CRTL != 0 {
        let c = byte(1);
        if c & (err::CRTL_RX_PASSIVE | err::CRTL_TX_PASSIVE) != 0 {
            return Some(BusState::ErrorPassive);
        }
        if c & (err::CRTL_RX_WARNING | err::CRTL_TX_WARNING) != 0 {
            return Some(BusState::ErrorWarning);
        }
        if c & err::CRTL_ACTIVE != 0 {
            return Some(BusState::ErrorActive);
        }
    }
    if class & err::RESTARTED != 0 {
        return Some(BusState::ErrorActive);
    }
    if class & err::CNT != 0 {
        let worst = byte(6).max(byte(7));
        return Some(if worst >= 128 {
            BusState::ErrorPassive
        } else if worst >= 96 {
            BusState::ErrorWarning
        } else {
            BusState::ErrorActive
        });
    }
    None
}

/// The error classes of an error frame in words (`bus-off, controller problem`), for logs.
pub fn describe_error_frame(frame: &Frame) -> String {
    const NAMES: [(u32, &str); 10] = [
        (err::TX_TIMEOUT, "TX timeout"),
        (err::LOSTARB, "lost arbitration"),
        (err::CRTL, "controller problem"),
        (err::PROT, "protocol violation"),
        (err::TRX, "transceiver fault"),
        (err::ACK, "no acknowledgement"),
        (err::BUSOFF, "bus-off"),
        (err::BUSERROR, "bus error"),
        (err::RESTARTED, "controller restarted"),
        (err::CNT, "error counters"),
    ];
    let class = frame.error_class();
    let mut words: Vec<String> = NAMES
        .iter()
        .filter(|(bit, _)| class & bit != 0)
        .map(|(_, n)| (*n).to_owned())
        .collect();
    let unknown = class & !NAMES.iter().fold(0, |a, (b, _)| a | b);
    if unknown != 0 {
        words.push(format!("unknown class {unknown:#x}"));
    }
    if words.is_empty() {
        words.push("no error class".to_owned());
    }
    words.join(", ")
}
