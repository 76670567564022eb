//! Tag memory banks from their scenario strings: the EPC-96, TID and user memory.

/// Parses an EPC-96 given as 24 hex digits.
pub fn parse_epc(hex: &str) -> Result<[u8; 12], String> {
    if hex.len() != 24 {
        return Err(format!(
            "must be 24 hex digits (EPC-96), got {} characters",
            hex.chars().count()
        ));
    }
    let mut out = [0u8; 12];
    for (i, byte) in out.iter_mut().enumerate() {
        let pair = hex.get(2 * i..2 * i + 2).ok_or("must be hex digits")?;
        *byte = u8::from_str_radix(pair, 16)
            .map_err(|_| format!("must be hex digits, got \"{hex}\""))?;
    }
    Ok(out)
}

/// Parses memory given as hex digits, a whole number of 16-bit words (4 digits each).
pub fn parse_words(hex: &str) -> Result<Vec<u16>, String> {
    if !hex.chars().all(|c| c.is_ascii_hexdigit()) {
        return Err(format!("must be hex digits, got \"{hex}\""));
    }
    if hex.len() % 4 != 0 {
        return Err(format!(
            "must be whole 16-bit words (a multiple of 4 hex digits), got {} digits",
            hex.len()
        ));
    }
    (0..hex.len() / 4)
        .map(|i| {
            u16::from_str_radix(&hex[4 * i..4 * i + 4], 16)
                .map_err(|_| format!("must be hex digits, got \"{hex}\""))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epc_and_words_parse() {
        let epc = parse_epc("300833B2DDD9014000000001").expect("valid EPC");
        assert_eq!(epc[0], 0x30);
        assert_eq!(epc[11], 0x01);
        assert!(parse_epc("300833B2DDD90140000000").is_err());
        assert!(parse_epc("300833B2DDD901400000000G").is_err());
        assert!(parse_epc("300833B2DDD9014000000é1").is_err());
        assert_eq!(
            parse_words("E2801160ABCD"),
            Ok(vec![0xE280, 0x1160, 0xABCD])
        );
        assert_eq!(parse_words(""), Ok(vec![]));
        assert!(parse_words("E28").is_err());
        assert!(parse_words("E28X").is_err());
    }
}
