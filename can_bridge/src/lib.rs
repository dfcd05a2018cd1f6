//! The CAN data server (the OA_NAVIO analogue of the ProCoSA paper): frames in and out, DBC
//! signals, event elaboration rules, bus health.
//!
//! Empty until the CAN data server is built (issue 6).
