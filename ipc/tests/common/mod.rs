//! Helpers shared by the integration tests.

use std::ops::Deref;

use petrel_ipc::Vehicle;

/// An isolated vehicle whose leftover files (iceoryx2 keeps a small global segment per prefix)
/// are removed when the test ends. Declare it before the participants, so it drops after them.
pub struct TestVehicle(pub Vehicle);

impl TestVehicle {
    pub fn new(name: &str) -> Self {
        TestVehicle(Vehicle::isolated(name).expect("valid name"))
    }
}

impl Deref for TestVehicle {
    type Target = Vehicle;
    fn deref(&self) -> &Vehicle {
        &self.0
    }
}

impl Drop for TestVehicle {
    fn drop(&mut self) {
        if let Err(e) = petrel_ipc::remove_vehicle_files(&self.0) {
            eprintln!("leftover files of {}: {e}", self.0.prefix());
        }
    }
}
