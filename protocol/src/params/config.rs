//! Reader configuration parameters not covered elsewhere (GET/SET_READER_CONFIG).
use crate::enums::IdentificationType;

llrp_struct! {
    /// Whether an antenna is connected, and its gain in hundredths of dBi.
    pub struct AntennaProperties: tlv [221] "AntennaProperties" {
        antenna_connected "AntennaConnected": bool = 1 bits; pad 7,
        antenna_id "AntennaID": u16,
        antenna_gain "AntennaGain": i16,
    } {}
}

llrp_struct! {
    /// The reader's identity: 0 MAC address, 1 EPC.
    pub struct Identification: tlv [218] "Identification" {
        id_type "IDType": IdentificationType,
        reader_id "ReaderID": Vec<u8>,
    } {}
}

llrp_struct! {
    /// A value that changes whenever the configuration does.
    pub struct LlrpConfigurationStateValue: tlv [217] "LLRPConfigurationStateValue" {
        llrp_configuration_state_value "LLRPConfigurationStateValue": u32,
    } {}
}

llrp_struct! {
    /// A GPI port's enablement and state.
    pub struct GpiPortCurrentState: tlv [225] "GPIPortCurrentState" {
        gpi_port_num "GPIPortNum": u16,
        config "Config": bool = 1 bits; pad 7,
        state "State": u8,
    } {}
}

llrp_struct! {
    /// A GPO port's output level.
    pub struct GpoWriteData: tlv [219] "GPOWriteData" {
        gpo_port_number "GPOPortNumber": u16,
        gpo_data "GPOData": bool = 1 bits; pad 7,
    } {}
}
