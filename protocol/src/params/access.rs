//! AccessSpecs: tag memory operations and their results.
use crate::enums::*;

use super::*;
use crate::codec::BitVec;

llrp_struct! {
    /// Tag memory operations to run on matching tags during an ROSpec.
    pub struct AccessSpec: tlv [207] "AccessSpec" {
        access_spec_id "AccessSpecID": u32,
        antenna_id "AntennaID": u16,
        protocol_id "ProtocolID": AirProtocol,
        current_state "CurrentState": bool = 1 bits; pad 7,
        ro_spec_id "ROSpecID": u32,
    } {
        access_spec_stop_trigger: one AccessSpecStopTrigger,
        access_command: one AccessCommand,
        access_report_spec: opt AccessReportSpec,
        custom: many Custom,
    }
}

llrp_struct! {
    /// AccessSpec stop: 0 null, 1 after `operation_count_value` runs.
    pub struct AccessSpecStopTrigger: tlv [208] "AccessSpecStopTrigger" {
        access_spec_stop_trigger_type "AccessSpecStopTriggerType": AccessSpecStopTriggerType,
        operation_count_value "OperationCountValue": u16,
    } {}
}

llrp_struct! {
    /// Which tags to access and the operations to run on them.
    pub struct AccessCommand: tlv [209] "AccessCommand" {} {
        c1g2_tag_spec: one C1g2TagSpec,
        op_specs: many1 OpSpec,
    }
}

llrp_choice! {
    /// One access operation.
    pub enum OpSpec "OpSpec" {
        C1g2Read(C1g2Read),
        C1g2Write(C1g2Write),
        C1g2Kill(C1g2Kill),
        C1g2Lock(C1g2Lock),
        C1g2BlockErase(C1g2BlockErase),
        C1g2BlockWrite(C1g2BlockWrite),
        ClientRequestOpSpec(ClientRequestOpSpec),
        Custom(Custom),
    }
}

llrp_struct! {
    /// An operation the client decides at run time.
    pub struct ClientRequestOpSpec: tlv [210] "ClientRequestOpSpec" {
        op_spec_id "OpSpecID": u16,
    } {}
}

llrp_struct! {
    /// The client's answer to CLIENT_REQUEST_OP.
    pub struct ClientRequestResponse: tlv [211] "ClientRequestResponse" {
        access_spec_id "AccessSpecID": u32,
    } {
        epc_data: one EpcData,
        op_specs: many OpSpec,
    }
}

llrp_struct! {
    /// One or two target tag patterns.
    pub struct C1g2TagSpec: tlv [338] "C1G2TagSpec" {} {
        c1g2_target_tag: many1 C1g2TargetTag,
    }
}

llrp_struct! {
    /// A memory pattern a tag must (or must not) match.
    pub struct C1g2TargetTag: tlv [339] "C1G2TargetTag" {
        mb "MB": u8 = 2 bits,
        is_match "Match": bool = 1 bits; pad 5,
        pointer "Pointer": u16,
        tag_mask "TagMask": BitVec,
        tag_data "TagData": BitVec,
    } {}
}

llrp_struct! {
    /// Read `word_count` words of bank `mb` from `word_pointer` (0 = whole bank).
    pub struct C1g2Read: tlv [341] "C1G2Read" {
        op_spec_id "OpSpecID": u16,
        access_password "AccessPassword": u32,
        mb "MB": u8 = 2 bits; pad 6,
        word_pointer "WordPointer": u16,
        word_count "WordCount": u16,
    } {}
}

llrp_struct! {
    /// Write words into bank `mb` from `word_pointer`.
    pub struct C1g2Write: tlv [342] "C1G2Write" {
        op_spec_id "OpSpecID": u16,
        access_password "AccessPassword": u32,
        mb "MB": u8 = 2 bits; pad 6,
        word_pointer "WordPointer": u16,
        write_data "WriteData": Vec<u16>,
    } {}
}

llrp_struct! {
    /// Kill the tag.
    pub struct C1g2Kill: tlv [343] "C1G2Kill" {
        op_spec_id "OpSpecID": u16,
        kill_password "KillPassword": u32,
    } {}
}

llrp_struct! {
    /// Lock or unlock memory banks and passwords.
    pub struct C1g2Lock: tlv [344] "C1G2Lock" {
        op_spec_id "OpSpecID": u16,
        access_password "AccessPassword": u32,
    } {
        c1g2_lock_payload: many1 C1g2LockPayload,
    }
}

llrp_struct! {
    /// One lock action: privilege and the memory it applies to.
    pub struct C1g2LockPayload: tlv [345] "C1G2LockPayload" {
        privilege "Privilege": u8,
        data_field "DataField": u8,
    } {}
}

llrp_struct! {
    /// Erase words of bank `mb`.
    pub struct C1g2BlockErase: tlv [346] "C1G2BlockErase" {
        op_spec_id "OpSpecID": u16,
        access_password "AccessPassword": u32,
        mb "MB": u8 = 2 bits; pad 6,
        word_pointer "WordPointer": u16,
        word_count "WordCount": u16,
    } {}
}

llrp_struct! {
    /// Write words of bank `mb` in blocks.
    pub struct C1g2BlockWrite: tlv [347] "C1G2BlockWrite" {
        op_spec_id "OpSpecID": u16,
        access_password "AccessPassword": u32,
        mb "MB": u8 = 2 bits; pad 6,
        word_pointer "WordPointer": u16,
        write_data "WriteData": Vec<u16>,
    } {}
}

llrp_choice! {
    /// The result of one access operation.
    pub enum OpSpecResult "OpSpecResult" {
        C1g2Read(C1g2ReadOpSpecResult),
        C1g2Write(C1g2WriteOpSpecResult),
        C1g2Kill(C1g2KillOpSpecResult),
        C1g2Lock(C1g2LockOpSpecResult),
        C1g2BlockErase(C1g2BlockEraseOpSpecResult),
        C1g2BlockWrite(C1g2BlockWriteOpSpecResult),
        ClientRequest(ClientRequestOpSpecResult),
    }
}

llrp_struct! {
    /// Result of a C1G2Read: 0 success, 1 nonspecific tag error, 2 no response, 3 nonspecific reader error, ...
    pub struct C1g2ReadOpSpecResult: tlv [349] "C1G2ReadOpSpecResult" {
        result "Result": u8,
        op_spec_id "OpSpecID": u16,
        read_data "ReadData": Vec<u16>,
    } {}
}

llrp_struct! {
    /// Result of a C1G2Write.
    pub struct C1g2WriteOpSpecResult: tlv [350] "C1G2WriteOpSpecResult" {
        result "Result": u8,
        op_spec_id "OpSpecID": u16,
        num_words_written "NumWordsWritten": u16,
    } {}
}

llrp_struct! {
    /// Result of a C1G2Kill.
    pub struct C1g2KillOpSpecResult: tlv [351] "C1G2KillOpSpecResult" {
        result "Result": u8,
        op_spec_id "OpSpecID": u16,
    } {}
}

llrp_struct! {
    /// Result of a C1G2Lock.
    pub struct C1g2LockOpSpecResult: tlv [352] "C1G2LockOpSpecResult" {
        result "Result": u8,
        op_spec_id "OpSpecID": u16,
    } {}
}

llrp_struct! {
    /// Result of a C1G2BlockErase.
    pub struct C1g2BlockEraseOpSpecResult: tlv [353] "C1G2BlockEraseOpSpecResult" {
        result "Result": u8,
        op_spec_id "OpSpecID": u16,
    } {}
}

llrp_struct! {
    /// Result of a C1G2BlockWrite.
    pub struct C1g2BlockWriteOpSpecResult: tlv [354] "C1G2BlockWriteOpSpecResult" {
        result "Result": u8,
        op_spec_id "OpSpecID": u16,
        num_words_written "NumWordsWritten": u16,
    } {}
}
