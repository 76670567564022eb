//! Declarative definitions: one macro call per parameter or message generates the struct,
//! its decoder, its encoder, serde support and (feature `arbitrary`) random generation, so
//! every layout in the spec tables is written exactly once.

/// Type of a sub-parameter slot.
macro_rules! slot_ty {
    (one $t:ty) => { $t };
    (opt $t:ty) => { Option<$t> };
    (many $t:ty) => { Vec<$t> };
    (many1 $t:ty) => { Vec<$t> };
}

/// Decodes a field: bit-packed when a width is given, byte-aligned otherwise.
macro_rules! field_dec {
    ($i:ident, $bit:ident, $t:ty, $w:literal) => {
        $crate::codec::take_bits($i, &mut $bit, $w)
            .map(|(r, v)| (r, <$t as $crate::codec::BitField>::from_bits(v)))
    };
    ($i:ident, $bit:ident, $t:ty) => {{
        debug_assert_eq!($bit, 0, "byte field after an incomplete bit group");
        <$t as $crate::codec::Field>::decode_field($i)
    }};
}

/// Encodes a field (see `field_dec`).
macro_rules! field_enc {
    ($buf:ident, $bw:ident, $v:expr, $t:ty, $w:literal) => {
        $bw.push($buf, $w, <$t as $crate::codec::BitField>::to_bits($v))
    };
    ($buf:ident, $bw:ident, $v:expr, $t:ty) => {
        <$t as $crate::codec::Field>::encode_field(&$v, $buf)
    };
}

/// Type of a sub-parameter slot while decoding (`one` slots start empty).
macro_rules! slot_local_ty {
    (one $t:ty) => { Option<$t> };
    (opt $t:ty) => { Option<$t> };
    (many $t:ty) => { Vec<$t> };
    (many1 $t:ty) => { Vec<$t> };
}

/// Whether a required slot is still empty.
macro_rules! slot_missing {
    (one, $v:ident) => {
        $v.is_none()
    };
    (many1, $v:ident) => {
        $v.is_empty()
    };
    ($k:ident, $v:ident) => {
        false
    };
}

/// Decodes the current parameter into its slot.
macro_rules! slot_put {
    (one, $walk:ident, $h:ident, $v:ident, $t:ty) => {
        slot_put!(opt, $walk, $h, $v, $t)
    };
    (opt, $walk:ident, $h:ident, $v:ident, $t:ty) => {
        if $v.is_some() {
            return Err($walk.duplicate(&$h));
        }
        $v = Some($walk.take::<$t>(&$h)?);
    };
    (many, $walk:ident, $h:ident, $v:ident, $t:ty) => {
        if $v.is_empty() {
            $walk.take_first::<$t>(&$h, &mut $v)?;
        } else {
            $v.push($walk.take::<$t>(&$h)?);
        }
    };
    (many1, $walk:ident, $h:ident, $v:ident, $t:ty) => {
        slot_put!(many, $walk, $h, $v, $t)
    };
}

/// The decoded slot's final value.
macro_rules! slot_final {
    (one, $walk:ident, $v:ident, $t:ty) => {
        match $v {
            Some(v) => v,
            None => return Err($walk.missing::<$t>()),
        }
    };
    ($k:ident, $walk:ident, $v:ident, $t:ty) => {
        $v
    };
}

/// Encodes a sub-parameter slot.
macro_rules! slot_enc {
    (one, $enc:ident, $v:expr) => {
        $enc.put(&$v)
    };
    (opt, $enc:ident, $v:expr) => {
        if let Some(p) = &$v {
            $enc.put(p)
        }
    };
    (many, $enc:ident, $v:expr) => {
        for p in &$v {
            $enc.put(p)
        }
    };
    (many1, $enc:ident, $v:expr) => {
        for p in &$v {
            $enc.put(p)
        }
    };
}

/// Random value of a field (feature `arbitrary`).
#[cfg(feature = "arbitrary")]
macro_rules! field_sample {
    ($g:ident, $t:ty; $($w:literal)?; $lo:literal, $hi:literal) => {{
        <$t as $crate::codec::Ranged>::from_raw($g.range($lo, $hi))
    }};
    ($g:ident, $t:ty; $w:literal; ) => {
        <$t as $crate::codec::BitField>::from_bits($g.bits($w))
    };
    ($g:ident, $t:ty; ; ) => {
        <$t as $crate::sample::Sample>::sample($g)
    };
}

/// Random value of a sub-parameter slot (feature `arbitrary`).
#[cfg(feature = "arbitrary")]
macro_rules! slot_sample {
    (one, $g:ident, $t:ty) => {
        $g.nested(|g| <$t as $crate::sample::Sample>::sample(g))
    };
    (opt, $g:ident, $t:ty) => {
        $g.option(|g| <$t as $crate::sample::Sample>::sample(g))
    };
    (many, $g:ident, $t:ty) => {
        $g.list(0, |g| <$t as $crate::sample::Sample>::sample(g))
    };
    (many1, $g:ident, $t:ty) => {
        $g.list(1, |g| <$t as $crate::sample::Sample>::sample(g))
    };
}

/// Number of sub-parameters a slot holds.
#[cfg(feature = "arbitrary")]
macro_rules! slot_count {
    (one, $v:expr) => {
        1usize
    };
    (opt, $v:expr) => {
        usize::from($v.is_some())
    };
    (many, $v:expr) => {
        $v.len()
    };
    (many1, $v:expr) => {
        $v.len()
    };
}

/// Defines a message or TLV/Custom parameter: struct, body codec, header codec, serde.
///
/// ```text
/// llrp_struct! {
///     /// doc
///     pub struct Name: tlv [177] "SpecName" {
///         field "FieldSpecName": u8,              // byte-aligned field
///         flag "Flag": bool = 1 bits; pad 7,      // bit field, then 7 reserved bits
///         prio "Priority": u8; in 0..=7,          // range-checked (A_OutOfRange)
///     } {
///         sub: one|opt|many|many1 SubType,        // sub-parameters in spec order
///     }
/// }
/// ```
/// Header kinds: `tlv TYPE`, `custom VENDOR SUBTYPE` (vendor parameter), `message TYPE`,
/// `custom_message VENDOR SUBTYPE`.
macro_rules! llrp_struct {
    (
        $(#[$meta:meta])*
        pub struct $name:ident : $kind:ident [$($num:literal)+] $spec:literal {
            $( $(#[$fmeta:meta])* $fname:ident $fspec:literal : $fty:ty
               $(= $w:literal bits)? $(; pad $p:literal)? $(; in $lo:literal ..= $hi:literal)? ),* $(,)?
        } {
            $( $(#[$smeta:meta])* $sname:ident : $skind:ident $sty:ty ),* $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Debug, Default, PartialEq, Eq)]
        #[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
        pub struct $name {
            $(
                #[doc = concat!("`", $fspec, "` field.")]
                $(#[$fmeta])*
                pub $fname: $fty,
            )*
            $(
                #[doc = concat!("`", stringify!($sty), "` sub-parameter (", stringify!($skind), ").")]
                $(#[$smeta])*
                #[cfg_attr(feature = "serde", serde(default, skip_serializing_if = "crate::codec::Absent::is_absent"))]
                pub $sname: slot_ty!($skind $sty),
            )*
            /// Unknown and out-of-slot vendor parameters, kept byte for byte in place.
            #[cfg_attr(feature = "serde", serde(default, skip_serializing_if = "Vec::is_empty"))]
            pub extra: Vec<$crate::raw::Extra>,
        }

        impl $name {
            /// Spec name.
            pub const SPEC_NAME: &'static str = $spec;
        }

        impl $crate::codec::Absent for $name {
            fn is_absent(&self) -> bool {
                false
            }
        }

        impl $crate::codec::Body for $name {
            #[allow(unused_mut, unused_variables, unused_assignments, unused_comparisons, clippy::manual_range_contains)]
            fn decode_body(i: &[u8]) -> Result<Self, $crate::error::DecodeError> {
                let mut bit = 0usize;
                let mut idx = 0u16;
                $(
                    let start = i;
                    let (i, $fname) = field_dec!(i, bit, $fty $(, $w)?)
                        .map_err($crate::codec::in_field($fspec, idx))?;
                    $(
                        let (i, _) = $crate::codec::take_bits(i, &mut bit, $p)
                            .map_err($crate::codec::in_field($fspec, idx))?;
                    )?
                    $(
                        let raw = $crate::codec::Ranged::raw(&$fname);
                        if raw < $lo || raw > $hi {
                            return Err($crate::codec::out_of_range(start, $fspec, idx));
                        }
                    )?
                    idx += 1;
                )*
                let mut walk = $crate::codec::Walk::new(i);
                $( let mut $sname: slot_local_ty!($skind $sty) = Default::default(); )*
                // Index of the slot the last parameter went to.
                let mut slot = 0usize;
                while let Some(h) = walk.header()? {
                    // The first slot at or after `slot` taking this parameter.
                    let mut k = 0usize;
                    let mut found = usize::MAX;
                    let mut any = false;
                    $(
                        if <$sty as $crate::codec::Param>::matches(&h) {
                            any = true;
                            if found == usize::MAX && k >= slot {
                                found = k;
                            }
                        }
                        k += 1;
                    )*
                    if found == usize::MAX {
                        if !any && $crate::codec::Walk::is_extra(&h) {
                            walk.set_aside(&h);
                            continue;
                        }
                        return Err(walk.unexpected(&h));
                    }
                    // Required slots passed over are missing.
                    let mut j = 0usize;
                    $(
                        if j >= slot && j < found && slot_missing!($skind, $sname) {
                            return Err(walk.missing::<$sty>());
                        }
                        j += 1;
                    )*
                    slot = found;
                    let mut j = 0usize;
                    $(
                        if j == found {
                            slot_put!($skind, walk, h, $sname, $sty);
                        }
                        j += 1;
                    )*
                }
                let mut j = 0usize;
                $(
                    if j >= slot && slot_missing!($skind, $sname) {
                        return Err(walk.missing::<$sty>());
                    }
                    j += 1;
                )*
                $( let $sname = slot_final!($skind, walk, $sname, $sty); )*
                let extra = walk.finish();
                Ok(Self { $($fname,)* $($sname,)* extra })
            }

            #[allow(unused_mut, unused_variables)]
            fn encode_body(&self, buf: &mut bytes::BytesMut) {
                let mut bw = $crate::codec::BitWriter::default();
                $(
                    field_enc!(buf, bw, self.$fname, $fty $(, $w)?);
                    $( bw.push(buf, $p, 0); )?
                )*
                let mut enc = $crate::codec::SubEnc::new(buf, &self.extra);
                $( slot_enc!($skind, enc, self.$sname); )*
                enc.finish();
            }
        }

        #[cfg(feature = "arbitrary")]
        impl $crate::sample::Sample for $name {
            #[allow(unused_variables, unused_mut)]
            fn sample(g: &mut $crate::sample::Gen) -> Self {
                $( let $fname = field_sample!(g, $fty; $($w)?; $($lo, $hi)?); )*
                $( let $sname = slot_sample!($skind, g, $sty); )*
                let n = 0usize $(+ slot_count!($skind, $sname))*;
                let extra = g.extras(n);
                Self { $($fname,)* $($sname,)* extra }
            }
        }

        llrp_struct!(@header $name $kind $($num)+ ; $spec);
    };

    (@header $name:ident tlv $ty:literal ; $spec:literal) => {
        impl $crate::codec::Param for $name {
            const NAME: &'static str = $spec;
            const TYPE: u16 = $ty;
            #[inline]
            fn matches(h: &$crate::codec::ParamHeader) -> bool {
                !h.tv() && h.ty() == $ty
            }
            fn decode_param(
                i: &[u8],
                _h: &$crate::codec::ParamHeader,
            ) -> Result<Self, $crate::error::DecodeError> {
                <Self as $crate::codec::Body>::decode_body(&i[4..]).map_err(|e| {
                    e.within($crate::error::PathSeg::Param { name: $spec, ty: $ty })
                })
            }
            fn encode_param(&self, buf: &mut bytes::BytesMut) {
                let start = $crate::codec::begin_tlv(buf, $ty);
                <Self as $crate::codec::Body>::encode_body(self, buf);
                $crate::codec::end_tlv(buf, start);
            }
        }
    };

    (@header $name:ident custom $vendor:literal $subtype:literal ; $spec:literal) => {
        impl $name {
            /// Vendor ID (IANA private enterprise number).
            pub const VENDOR: u32 = $vendor;
            /// Vendor parameter subtype.
            pub const SUBTYPE: u32 = $subtype;
        }

        impl $crate::codec::Param for $name {
            const NAME: &'static str = $spec;
            const TYPE: u16 = $crate::codec::CUSTOM_TYPE;
            #[inline]
            fn matches(h: &$crate::codec::ParamHeader) -> bool {
                !h.tv() && h.ty() == $crate::codec::CUSTOM_TYPE && h.vendor() == $vendor && h.subtype() == $subtype
            }
            fn decode_param(
                i: &[u8],
                _h: &$crate::codec::ParamHeader,
            ) -> Result<Self, $crate::error::DecodeError> {
                <Self as $crate::codec::Body>::decode_body(&i[12..]).map_err(|e| {
                    e.within($crate::error::PathSeg::Param {
                        name: $spec,
                        ty: $crate::codec::CUSTOM_TYPE,
                    })
                })
            }
            fn encode_param(&self, buf: &mut bytes::BytesMut) {
                use bytes::BufMut;
                let start = $crate::codec::begin_tlv(buf, $crate::codec::CUSTOM_TYPE);
                buf.put_u32($vendor);
                buf.put_u32($subtype);
                <Self as $crate::codec::Body>::encode_body(self, buf);
                $crate::codec::end_tlv(buf, start);
            }
        }
    };

    (@header $name:ident message $ty:literal ; $spec:literal) => {
        impl $crate::message::MessageDef for $name {
            const NAME: &'static str = $spec;
            const TYPE: u16 = $ty;
        }
    };

    (@header $name:ident custom_message $vendor:literal $subtype:literal ; $spec:literal) => {
        impl $crate::message::CustomMessageDef for $name {
            const NAME: &'static str = $spec;
            const VENDOR: u32 = $vendor;
            const SUBTYPE: u8 = $subtype;
        }
    };
}

/// Defines a TV parameter holding one value.
macro_rules! tv_param {
    ($(#[$meta:meta])* $name:ident, $ty:literal, $spec:literal, $vty:ty $(, #[$vattr:meta])?) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
        #[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
        #[cfg_attr(feature = "serde", serde(transparent))]
        pub struct $name($(#[$vattr])? pub $vty);

        impl $crate::codec::Param for $name {
            const NAME: &'static str = $spec;
            const TYPE: u16 = $ty;
            #[inline]
            fn matches(h: &$crate::codec::ParamHeader) -> bool {
                h.tv() && h.ty() == $ty
            }
            #[inline]
            fn decode_param(
                i: &[u8],
                _h: &$crate::codec::ParamHeader,
            ) -> Result<Self, $crate::error::DecodeError> {
                // The header check guarantees the value's bytes are present.
                <$vty as $crate::codec::Field>::decode_field(&i[1..])
                    .map(|(_, v)| $name(v))
                    .map_err(|e| e.within($crate::error::PathSeg::Param { name: $spec, ty: $ty }))
            }
            #[inline]
            fn encode_param(&self, buf: &mut bytes::BytesMut) {
                use bytes::BufMut;
                buf.put_u8(0x80 | $ty);
                <$vty as $crate::codec::Field>::encode_field(&self.0, buf);
            }
        }

        impl $crate::codec::Absent for $name {
            fn is_absent(&self) -> bool {
                false
            }
        }

        #[cfg(feature = "arbitrary")]
        impl $crate::sample::Sample for $name {
            fn sample(g: &mut $crate::sample::Gen) -> Self {
                $name(<$vty as $crate::sample::Sample>::sample(g))
            }
        }
    };
}

/// Defines a sub-parameter slot that takes one of several parameter types.
macro_rules! llrp_choice {
    // `no_sample`: the caller writes `Sample` by hand (to avoid ambiguous orders).
    (no_sample $(#[$meta:meta])* pub enum $name:ident $spec:literal { $first:ident($fty:ty) $(, $var:ident($vty:ty))* $(,)? }) => {
        llrp_choice!(@core $(#[$meta])* pub enum $name $spec { $first($fty) $(, $var($vty))* });
    };
    ($(#[$meta:meta])* pub enum $name:ident $spec:literal { $first:ident($fty:ty) $(, $var:ident($vty:ty))* $(,)? }) => {
        llrp_choice!(@core $(#[$meta])* pub enum $name $spec { $first($fty) $(, $var($vty))* });

        #[cfg(feature = "arbitrary")]
        impl $crate::sample::Sample for $name {
            #[allow(unused_mut)]
            fn sample(g: &mut $crate::sample::Gen) -> Self {
                let mut choices: Vec<fn(&mut $crate::sample::Gen) -> $name> =
                    vec![|g| $name::$first(<$fty as $crate::sample::Sample>::sample(g))];
                $( choices.push(|g| $name::$var(<$vty as $crate::sample::Sample>::sample(g))); )*
                let k = g.index(choices.len());
                choices[k](g)
            }
        }
    };
    (@core $(#[$meta:meta])* pub enum $name:ident $spec:literal { $first:ident($fty:ty) $(, $var:ident($vty:ty))* }) => {
        $(#[$meta])*
        #[derive(Clone, Debug, PartialEq, Eq)]
        #[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
        #[allow(missing_docs)]
        pub enum $name {
            $first($fty),
            $($var($vty),)*
        }

        impl Default for $name {
            fn default() -> Self {
                $name::$first(Default::default())
            }
        }

        impl $crate::codec::Param for $name {
            const NAME: &'static str = $spec;
            const TYPE: u16 = <$fty as $crate::codec::Param>::TYPE;
            #[inline]
            fn matches(h: &$crate::codec::ParamHeader) -> bool {
                <$fty as $crate::codec::Param>::matches(h) $(|| <$vty as $crate::codec::Param>::matches(h))*
            }
            fn decode_param(
                i: &[u8],
                h: &$crate::codec::ParamHeader,
            ) -> Result<Self, $crate::error::DecodeError> {
                if <$fty as $crate::codec::Param>::matches(h) {
                    return <$fty as $crate::codec::Param>::decode_param(i, h).map($name::$first);
                }
                $(
                    if <$vty as $crate::codec::Param>::matches(h) {
                        return <$vty as $crate::codec::Param>::decode_param(i, h).map($name::$var);
                    }
                )*
                Err($crate::error::DecodeError::at(
                    i.as_ptr(),
                    $crate::error::ErrorKind::UnexpectedParameter { ty: h.ty() },
                ))
            }
            fn encode_param(&self, buf: &mut bytes::BytesMut) {
                match self {
                    $name::$first(p) => p.encode_param(buf),
                    $($name::$var(p) => p.encode_param(buf),)*
                }
            }
        }

        impl $crate::codec::Absent for $name {
            fn is_absent(&self) -> bool {
                false
            }
        }
    };
}
