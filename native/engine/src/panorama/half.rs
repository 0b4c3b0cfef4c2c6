//! IEEE half-precision to f32, exact (the scalar twin of the F16C instruction).

#[inline]
pub fn to_f32(h: u16) -> f32 {
    let sign = ((h as u32) & 0x8000) << 16;
    let exponent = ((h >> 10) & 0x1f) as u32;
    let mantissa = (h & 0x3ff) as u32;
    let bits = match exponent {
        0 if mantissa == 0 => sign,
        0 => {
            // Subnormal: mantissa * 2^-24, exactly representable in f32.
            let value = mantissa as f32 * (1.0 / 16_777_216.0);
            return if sign != 0 { -value } else { value };
        }
        0x1f => sign | 0x7f80_0000 | (mantissa << 13),
        _ => sign | ((exponent + 112) << 23) | (mantissa << 13),
    };
    f32::from_bits(bits)
}

#[cfg(test)]
mod tests {
    #[test]
    fn known_values() {
        assert_eq!(super::to_f32(0x3c00), 1.0);
        assert_eq!(super::to_f32(0xc000), -2.0);
        assert_eq!(super::to_f32(0x7bff), 65504.0);
        assert_eq!(super::to_f32(0x0001), 5.960_464_5e-8);
        assert_eq!(super::to_f32(0x8001), -5.960_464_5e-8);
        assert_eq!(super::to_f32(0x3555), 0.333_251_95);
    }
}
