//! sim-device: a fake valve positioner speaking Modbus (filled in by the Modbus work).
fn main() {
    eprintln!("sim-device: the Modbus server is not built yet");
    std::process::exit(2);
}
