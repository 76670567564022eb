//! Enumerated fields as Rust enums: each has the values the specification names and an
//! `Unknown(n)` variant for any other, so decoding stays lossless and callers match on names
//! instead of numbers. On the wire and in serde they are their number.

/// Defines an enumerated field type over an unsigned integer.
macro_rules! llrp_enum {
    (
        $(#[$meta:meta])*
        pub enum $name:ident : $raw:ty {
            $( $(#[$vmeta:meta])* $var:ident = $val:literal ),+ $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum $name {
            $( $(#[$vmeta])* $var, )+
            /// A value the specification does not name, kept as it came.
            Unknown($raw),
        }

        impl $name {
            /// Every named value, in numeric order.
            pub const ALL: &'static [$name] = &[$($name::$var),+];

            /// The value on the wire.
            pub const fn value(self) -> $raw {
                match self {
                    $( $name::$var => $val, )+
                    $name::Unknown(v) => v,
                }
            }

            /// The named value for `v`, or `Unknown(v)`.
            pub const fn from_value(v: $raw) -> Self {
                match v {
                    $( $val => $name::$var, )+
                    other => $name::Unknown(other),
                }
            }

            /// Whether the specification names this value.
            pub const fn is_known(self) -> bool {
                !matches!(self, $name::Unknown(_))
            }
        }

        impl Default for $name {
            /// The value 0 (what an all-zero field decodes to).
            fn default() -> Self {
                $name::from_value(0)
            }
        }

        impl From<$raw> for $name {
            fn from(v: $raw) -> Self {
                $name::from_value(v)
            }
        }

        impl From<$name> for $raw {
            fn from(v: $name) -> Self {
                v.value()
            }
        }

        impl $crate::codec::Field for $name {
            #[inline]
            fn decode_field(i: &[u8]) -> $crate::codec::FieldResult<'_, Self> {
                <$raw as $crate::codec::Field>::decode_field(i).map(|(r, v)| (r, $name::from_value(v)))
            }
            #[inline]
            fn encode_field(&self, buf: &mut bytes::BytesMut) {
                <$raw as $crate::codec::Field>::encode_field(&self.value(), buf)
            }
        }

        impl $crate::codec::Ranged for $name {
            type Raw = $raw;
            fn raw(&self) -> $raw {
                self.value()
            }
            fn from_raw(v: $raw) -> Self {
                $name::from_value(v)
            }
        }

        #[cfg(feature = "serde")]
        impl serde::Serialize for $name {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                serde::Serialize::serialize(&self.value(), s)
            }
        }

        #[cfg(feature = "serde")]
        impl<'de> serde::Deserialize<'de> for $name {
            fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                <$raw as serde::Deserialize>::deserialize(d).map($name::from_value)
            }
        }

        #[cfg(feature = "arbitrary")]
        impl $crate::sample::Sample for $name {
            fn sample(g: &mut $crate::sample::Gen) -> Self {
                // Mostly named values, sometimes another one (decoding must keep it).
                if g.index(8) == 0 {
                    $name::from_value(<$raw as $crate::sample::Sample>::sample(g))
                } else {
                    $name::ALL[g.index($name::ALL.len())]
                }
            }
        }
    };
}

llrp_enum! {
    /// ROSpecStartTrigger.ROSpecStartTriggerType.
    pub enum RoSpecStartTriggerType: u8 {
        /// Only START_ROSPEC starts the ROSpec.
        Null = 0,
        /// Starts as soon as it is enabled.
        Immediate = 1,
        /// Starts at an offset and then every period (PeriodicTriggerValue).
        Periodic = 2,
        /// Starts on a GPI event (GPITriggerValue).
        Gpi = 3,
    }
}

llrp_enum! {
    /// ROSpecStopTrigger.ROSpecStopTriggerType.
    pub enum RoSpecStopTriggerType: u8 {
        /// Ends when its AISpecs are done, or on STOP_ROSPEC.
        Null = 0,
        /// Ends after DurationTriggerValue ms.
        Duration = 1,
        /// Ends on a GPI event, or after its timeout.
        GpiWithTimeout = 2,
    }
}

llrp_enum! {
    /// AISpecStopTrigger.AISpecStopTriggerType.
    pub enum AiSpecStopTriggerType: u8 {
        /// Ends only with its ROSpec.
        Null = 0,
        /// Ends after DurationTrigger ms.
        Duration = 1,
        /// Ends on a GPI event, or after its timeout.
        GpiWithTimeout = 2,
        /// Ends on a TagObservationTrigger.
        TagObservation = 3,
    }
}

llrp_enum! {
    /// TagObservationTrigger.TriggerType.
    pub enum TagObservationTriggerType: u8 {
        /// Upon seeing NumberOfTags tags, or the timeout.
        UponSeeingNTagsOrTimeout = 0,
        /// Upon seeing no new tag for T ms, or the timeout.
        UponSeeingNoMoreNewTagsForTmsOrTimeout = 1,
        /// After NumberOfAttempts inventory attempts, or the timeout.
        NAttemptsToSeeAllTagsInFovOrTimeout = 2,
        /// LLRP 1.1: upon seeing NumberOfTags unique tags, or the timeout.
        UponSeeingNUniqueTagsOrTimeout = 3,
        /// LLRP 1.1: upon seeing no new unique tag for T ms, or the timeout.
        UponSeeingNoMoreNewUniqueTagsForTmsOrTimeout = 4,
    }
}

llrp_enum! {
    /// AccessSpecStopTrigger.AccessSpecStopTriggerType.
    pub enum AccessSpecStopTriggerType: u8 {
        /// No stop trigger.
        Null = 0,
        /// Ends after OperationCountValue executions.
        OperationCount = 1,
    }
}

llrp_enum! {
    /// ROReportSpec.ROReportTrigger.
    pub enum RoReportTriggerType: u8 {
        /// Only GET_REPORT reports.
        None = 0,
        /// Upon N tags, or at the end of the AISpec.
        UponNTagsOrEndOfAiSpec = 1,
        /// Upon N tags, or at the end of the ROSpec.
        UponNTagsOrEndOfRoSpec = 2,
        /// LLRP 1.1: upon N seconds, or at the end of the AISpec.
        UponNSecondsOrEndOfAiSpec = 3,
        /// LLRP 1.1: upon N seconds, or at the end of the ROSpec.
        UponNSecondsOrEndOfRoSpec = 4,
        /// LLRP 1.1: upon N milliseconds, or at the end of the AISpec.
        UponNMillisecondsOrEndOfAiSpec = 5,
        /// LLRP 1.1: upon N milliseconds, or at the end of the ROSpec.
        UponNMillisecondsOrEndOfRoSpec = 6,
    }
}

llrp_enum! {
    /// AccessReportSpec.AccessReportTrigger.
    pub enum AccessReportTriggerType: u8 {
        /// Access results go with the RO reports.
        WheneverRoReportIsGenerated = 0,
        /// Access results are reported at the end of the AccessSpec.
        EndOfAccessSpec = 1,
    }
}

llrp_enum! {
    /// Identification.IDType.
    pub enum IdentificationType: u8 {
        /// ReaderID is a MAC address.
        MacAddress = 0,
        /// ReaderID is an EPC.
        Epc = 1,
    }
}

llrp_enum! {
    /// ConnectionAttemptEvent.Status.
    pub enum ConnectionAttemptStatus: u16 {
        /// The connection is accepted.
        Success = 0,
        /// Refused: a reader-initiated connection already exists.
        FailedReaderInitiatedConnectionExists = 1,
        /// Refused: a client-initiated connection already exists.
        FailedClientInitiatedConnectionExists = 2,
        /// Refused for another reason.
        FailedOtherReason = 3,
        /// Sent to the connected client: another client tried to connect.
        AnotherConnectionAttempted = 4,
    }
}

llrp_enum! {
    /// ROSpecEvent.EventType.
    pub enum RoSpecEventType: u8 {
        /// The ROSpec started.
        StartOfRoSpec = 0,
        /// The ROSpec ended.
        EndOfRoSpec = 1,
        /// The ROSpec was preempted by another.
        PreemptionOfRoSpec = 2,
    }
}

llrp_enum! {
    /// AISpecEvent.EventType.
    pub enum AiSpecEventType: u8 {
        /// The AISpec ended.
        EndOfAiSpec = 0,
    }
}

llrp_enum! {
    /// AntennaEvent.EventType.
    pub enum AntennaEventType: u8 {
        /// The antenna was disconnected.
        AntennaDisconnected = 0,
        /// The antenna was connected.
        AntennaConnected = 1,
    }
}

llrp_enum! {
    /// EventNotificationState.EventType: which reader events a client is sent.
    pub enum NotificationEventType: u16 {
        /// HoppingEvent.
        UponHoppingToNextChannel = 0,
        /// GPIEvent.
        GpiEvent = 1,
        /// ROSpecEvent.
        RoSpecEvent = 2,
        /// ReportBufferLevelWarningEvent.
        ReportBufferFillWarning = 3,
        /// ReaderExceptionEvent.
        ReaderExceptionEvent = 4,
        /// RFSurveyEvent.
        RfSurveyEvent = 5,
        /// AISpecEvent.
        AiSpecEvent = 6,
        /// AISpecEvent with details.
        AiSpecEventWithDetails = 7,
        /// AntennaEvent.
        AntennaEvent = 8,
        /// LLRP 1.1: SpecLoopEvent.
        SpecLoopEvent = 9,
    }
}

llrp_enum! {
    /// KeepaliveSpec.KeepaliveTriggerType.
    pub enum KeepaliveTriggerType: u8 {
        /// No keepalives.
        Null = 0,
        /// A KEEPALIVE every PeriodicTriggerValue ms.
        Periodic = 1,
    }
}

llrp_enum! {
    /// An air protocol (InventoryParameterSpec.ProtocolID, AccessSpec.ProtocolID).
    pub enum AirProtocol: u8 {
        /// Unspecified.
        Unspecified = 0,
        /// EPCglobal Class 1 Gen 2 (ISO/IEC 18000-63).
        EpcGlobalClass1Gen2 = 1,
    }
}

llrp_enum! {
    /// ROSpec.CurrentState.
    pub enum RoSpecState: u8 {
        /// Added, not enabled.
        Disabled = 0,
        /// Enabled, waiting for its start trigger.
        Inactive = 1,
        /// Executing.
        Active = 2,
    }
}

llrp_enum! {
    /// GET_READER_CAPABILITIES.RequestedData.
    pub enum CapabilitiesRequest: u8 {
        /// Every capability.
        All = 0,
        /// GeneralDeviceCapabilities.
        GeneralDeviceCapabilities = 1,
        /// LLRPCapabilities.
        LlrpCapabilities = 2,
        /// RegulatoryCapabilities.
        RegulatoryCapabilities = 3,
        /// The air protocol's capabilities (C1G2LLRPCapabilities).
        AirProtocolLlrpCapabilities = 4,
    }
}

llrp_enum! {
    /// GET_READER_CONFIG.RequestedData.
    pub enum ConfigRequest: u8 {
        /// Every configuration item.
        All = 0,
        /// Identification.
        Identification = 1,
        /// AntennaProperties.
        AntennaProperties = 2,
        /// AntennaConfiguration.
        AntennaConfiguration = 3,
        /// ROReportSpec.
        RoReportSpec = 4,
        /// ReaderEventNotificationSpec.
        ReaderEventNotificationSpec = 5,
        /// AccessReportSpec.
        AccessReportSpec = 6,
        /// LLRPConfigurationStateValue.
        LlrpConfigurationStateValue = 7,
        /// KeepaliveSpec.
        KeepaliveSpec = 8,
        /// GPIPortCurrentState.
        GpiPortCurrentState = 9,
        /// GPOWriteData.
        GpoWriteData = 10,
        /// EventsAndReports.
        EventsAndReports = 11,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn named_values_round_trip_and_others_are_kept() {
        for &t in RoReportTriggerType::ALL {
            assert_eq!(RoReportTriggerType::from_value(t.value()), t);
            assert!(t.is_known());
        }
        assert_eq!(
            RoSpecStartTriggerType::from_value(1),
            RoSpecStartTriggerType::Immediate
        );
        let other = NotificationEventType::from_value(42);
        assert_eq!(other, NotificationEventType::Unknown(42));
        assert_eq!(other.value(), 42);
        assert!(!other.is_known());
        assert_eq!(RoSpecState::default(), RoSpecState::Disabled);
    }
}
