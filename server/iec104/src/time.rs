//! CP56Time2a: the seven-octet time tag of IEC 60870-5-4, the only one IEC 104
//! allows (CP24Time2a is forbidden there, so it is not here).
//!
//! Layout, low octet first:
//! 1-2. milliseconds including seconds (u16 LE, 0..=59999)
//! 3. minute (bits 0-5), IV invalid (bit 7)
//! 4. hour (bits 0-4), SU summer time (bit 7)
//! 5. day of month (bits 0-4), day of week (bits 5-7, 1 = Monday, 0 = not used)
//! 6. month (bits 0-3)
//! 7. year (bits 0-6, 0..=99 for 2000..=2099)
//!
//! Reserved bits are ignored when decoding and written as zero. The fields are
//! read as UTC: the SU bit is carried, never applied, because 104 devices that
//! send local time are configured per station, not per frame.

use thiserror::Error;

/// Octets of a CP56Time2a.
pub const CP56_LEN: usize = 7;

/// Unix milliseconds of 2000-01-01T00:00:00Z, the first instant CP56Time2a can hold.
const MIN_UNIX_MS: i64 = 946_684_800_000;
/// Unix milliseconds of 2100-01-01T00:00:00Z, the first instant past its range.
const END_UNIX_MS: i64 = 4_102_444_800_000;
const MS_PER_DAY: i64 = 86_400_000;

/// A field of a CP56Time2a that no calendar has, or an instant it cannot hold.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum TimeError {
    #[error("CP56Time2a needs 7 octets, got {0}")]
    Short(usize),
    #[error("CP56Time2a milliseconds {0} out of range 0..=59999")]
    Millisecond(u16),
    #[error("CP56Time2a minute {0} out of range 0..=59")]
    Minute(u8),
    #[error("CP56Time2a hour {0} out of range 0..=23")]
    Hour(u8),
    #[error("CP56Time2a day {day} out of range 1..={last} for month {month} of year {year}")]
    Day {
        day: u8,
        month: u8,
        year: u16,
        last: u8,
    },
    #[error("CP56Time2a day of week {0} out of range 0..=7")]
    DayOfWeek(u8),
    #[error("CP56Time2a month {0} out of range 1..=12")]
    Month(u8),
    #[error("CP56Time2a year {0} out of range 0..=99")]
    Year(u8),
    #[error("Unix time {0} ms is outside 2000..=2099, the range of CP56Time2a")]
    OutOfRange(i64),
}

/// A CP56Time2a time tag, field by field as on the wire.
///
/// Fields are public so that a tag received with an odd but legal value (a day
/// of week of 0, the IV bit) is kept as sent; [`Cp56Time2a::validate`] says
/// whether a hand-built one can be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Cp56Time2a {
    /// Milliseconds within the minute, seconds included (0..=59999).
    pub millisecond: u16,
    /// 0..=59.
    pub minute: u8,
    /// 0..=23.
    pub hour: u8,
    /// Day of month, 1..=31 (and within the month's length).
    pub day: u8,
    /// 1 = Monday ..= 7 = Sunday; 0 when the sender does not use it.
    pub day_of_week: u8,
    /// 1..=12.
    pub month: u8,
    /// Years since 2000, 0..=99.
    pub year: u8,
    /// IV: the sender's clock is not to be trusted (not synchronised).
    pub invalid: bool,
    /// SU: the fields are in summer time.
    pub summer_time: bool,
}

impl Cp56Time2a {
    /// Decode the first seven octets of `b`; reserved bits are ignored.
    pub fn decode(b: &[u8]) -> Result<Self, TimeError> {
        let b: &[u8; CP56_LEN] = b
            .get(..CP56_LEN)
            .and_then(|s| s.try_into().ok())
            .ok_or(TimeError::Short(b.len()))?;
        let t = Cp56Time2a {
            millisecond: u16::from_le_bytes([b[0], b[1]]),
            minute: b[2] & 0x3F,
            invalid: b[2] & 0x80 != 0,
            hour: b[3] & 0x1F,
            summer_time: b[3] & 0x80 != 0,
            day: b[4] & 0x1F,
            day_of_week: b[4] >> 5,
            month: b[5] & 0x0F,
            year: b[6] & 0x7F,
        };
        t.validate()?;
        Ok(t)
    }

    /// The seven octets. Fields are masked to their widths: call
    /// [`validate`](Self::validate) first for a hand-built value.
    pub fn encode(&self) -> [u8; CP56_LEN] {
        let ms = self.millisecond.to_le_bytes();
        [
            ms[0],
            ms[1],
            (self.minute & 0x3F) | if self.invalid { 0x80 } else { 0 },
            (self.hour & 0x1F) | if self.summer_time { 0x80 } else { 0 },
            (self.day & 0x1F) | ((self.day_of_week & 0x07) << 5),
            self.month & 0x0F,
            self.year & 0x7F,
        ]
    }

    /// Whether every field is one a calendar has.
    pub fn validate(&self) -> Result<(), TimeError> {
        if self.millisecond > 59_999 {
            return Err(TimeError::Millisecond(self.millisecond));
        }
        if self.minute > 59 {
            return Err(TimeError::Minute(self.minute));
        }
        if self.hour > 23 {
            return Err(TimeError::Hour(self.hour));
        }
        if self.year > 99 {
            return Err(TimeError::Year(self.year));
        }
        if !(1..=12).contains(&self.month) {
            return Err(TimeError::Month(self.month));
        }
        if self.day_of_week > 7 {
            return Err(TimeError::DayOfWeek(self.day_of_week));
        }
        let year = 2000 + u16::from(self.year);
        let last = days_in_month(year, self.month);
        if self.day == 0 || self.day > last {
            return Err(TimeError::Day {
                day: self.day,
                month: self.month,
                year,
                last,
            });
        }
        Ok(())
    }

    /// The tag for a Unix time in milliseconds (UTC), with the day of week
    /// filled in and IV and SU clear.
    pub fn from_unix_ms(unix_ms: i64) -> Result<Self, TimeError> {
        if !(MIN_UNIX_MS..END_UNIX_MS).contains(&unix_ms) {
            return Err(TimeError::OutOfRange(unix_ms));
        }
        let days = unix_ms.div_euclid(MS_PER_DAY);
        let in_day = unix_ms.rem_euclid(MS_PER_DAY);
        let (year, month, day) = civil_from_days(days);
        // 1970-01-01 was a Thursday (ISO day 4).
        let day_of_week = (days + 3).rem_euclid(7) + 1;
        // The range check above bounds every field, so the casts cannot truncate.
        Ok(Cp56Time2a {
            millisecond: (in_day % 60_000) as u16,
            minute: (in_day / 60_000 % 60) as u8,
            hour: (in_day / 3_600_000) as u8,
            day: day as u8,
            day_of_week: day_of_week as u8,
            month: month as u8,
            year: (year - 2000) as u8,
            invalid: false,
            summer_time: false,
        })
    }

    /// The same tag with the IV bit set or clear.
    pub fn with_invalid(mut self, invalid: bool) -> Self {
        self.invalid = invalid;
        self
    }

    /// The same tag with the SU bit set or clear.
    pub fn with_summer_time(mut self, summer_time: bool) -> Self {
        self.summer_time = summer_time;
        self
    }

    /// Unix milliseconds (UTC) of the fields; IV and SU stay on the tag for the
    /// caller to weigh. The day of week is not checked against the date:
    /// devices that do not use it send 0, and a wrong one says nothing about
    /// the instant.
    pub fn to_unix_ms(&self) -> Result<i64, TimeError> {
        self.validate()?;
        let days = days_from_civil(
            2000 + i64::from(self.year),
            i64::from(self.month),
            i64::from(self.day),
        );
        Ok(days * MS_PER_DAY
            + i64::from(self.hour) * 3_600_000
            + i64::from(self.minute) * 60_000
            + i64::from(self.millisecond))
    }
}

fn is_leap(year: u16) -> bool {
    year.is_multiple_of(4) && (!year.is_multiple_of(100) || year.is_multiple_of(400))
}

/// Length of a month (1..=12) in the proleptic Gregorian calendar.
fn days_in_month(year: u16, month: u8) -> u8 {
    match month {
        2 if is_leap(year) => 29,
        2 => 28,
        4 | 6 | 9 | 11 => 30,
        _ => 31,
    }
}

/// Days since 1970-01-01 of a civil date (H. Hinnant's algorithm).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// The civil date (year, month, day) of days since 1970-01-01.
fn civil_from_days(z: i64) -> (i64, i64, i64) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Cp56Time2a {
        // 2024-02-29T23:59:59.999Z, a Thursday.
        Cp56Time2a {
            millisecond: 59_999,
            minute: 59,
            hour: 23,
            day: 29,
            day_of_week: 4,
            month: 2,
            year: 24,
            invalid: false,
            summer_time: false,
        }
    }

    #[test]
    fn unix_round_trip_at_the_edges() {
        for ms in [
            MIN_UNIX_MS,
            MIN_UNIX_MS + 1,
            1_709_251_199_999, // 2024-02-29T23:59:59.999Z
            1_709_251_200_000, // 2024-03-01
            951_782_400_000,   // 2000-02-29 (a leap day: 2000 is divisible by 400)
            END_UNIX_MS - 1,
        ] {
            let t = Cp56Time2a::from_unix_ms(ms).unwrap();
            assert_eq!(t.to_unix_ms().unwrap(), ms, "{t:?}");
            assert_eq!(Cp56Time2a::decode(&t.encode()).unwrap(), t);
        }
        assert_eq!(
            Cp56Time2a::from_unix_ms(1_709_251_199_999).unwrap(),
            sample()
        );
    }

    #[test]
    fn every_day_of_the_range_round_trips() {
        let mut ms = MIN_UNIX_MS + 12_345;
        // 2000-01-01 was a Saturday, so the day before is a Friday.
        let mut last_dow = 5;
        while ms < END_UNIX_MS {
            let t = Cp56Time2a::from_unix_ms(ms).unwrap();
            assert_eq!(t.to_unix_ms().unwrap(), ms);
            assert_eq!(t.day_of_week, last_dow % 7 + 1, "{t:?}");
            last_dow = t.day_of_week;
            ms += MS_PER_DAY;
        }
    }

    #[test]
    fn out_of_range_instants_are_refused() {
        for ms in [MIN_UNIX_MS - 1, END_UNIX_MS, 0, -1, i64::MIN, i64::MAX] {
            assert_eq!(Cp56Time2a::from_unix_ms(ms), Err(TimeError::OutOfRange(ms)));
        }
    }

    #[test]
    fn known_octets() {
        // 2024-02-29 23:59:59.999, IV and SU set, Thursday.
        let bytes = [0x5F, 0xEA, 0xBB, 0x97, 0x9D, 0x02, 0x18];
        let t = Cp56Time2a::decode(&bytes).unwrap();
        assert_eq!(t, sample().with_invalid(true).with_summer_time(true));
        assert_eq!(t.encode(), bytes);
        // Reserved bits are ignored on decode and cleared on encode.
        let noisy = [0x5F, 0xEA, 0xFB, 0xF7, 0x9D, 0xF2, 0x98];
        assert_eq!(Cp56Time2a::decode(&noisy).unwrap(), t);
    }

    #[test]
    fn field_limits() {
        let ok = sample().encode();
        let with = |i: usize, v: u8| {
            let mut b = ok;
            b[i] = v;
            Cp56Time2a::decode(&b)
        };
        // Milliseconds: 59999 is the last.
        let mut b = ok;
        b[..2].copy_from_slice(&59_999u16.to_le_bytes());
        assert!(Cp56Time2a::decode(&b).is_ok());
        b[..2].copy_from_slice(&60_000u16.to_le_bytes());
        assert_eq!(Cp56Time2a::decode(&b), Err(TimeError::Millisecond(60_000)));
        b[..2].copy_from_slice(&0u16.to_le_bytes());
        assert!(Cp56Time2a::decode(&b).is_ok());
        // Minute 0..=59 (six bits reach 63).
        assert!(with(2, 0).is_ok());
        assert!(with(2, 59).is_ok());
        assert_eq!(with(2, 60), Err(TimeError::Minute(60)));
        assert_eq!(with(2, 63), Err(TimeError::Minute(63)));
        // Hour 0..=23 (five bits reach 31).
        assert!(with(3, 0).is_ok());
        assert!(with(3, 23).is_ok());
        assert_eq!(with(3, 24), Err(TimeError::Hour(24)));
        assert_eq!(with(3, 31), Err(TimeError::Hour(31)));
        // Day 1..=length of the month; day of week any of its 3 bits.
        assert!(with(4, 1).is_ok());
        assert!(matches!(with(4, 0), Err(TimeError::Day { day: 0, .. })));
        assert!(matches!(
            with(4, 30),
            Err(TimeError::Day {
                day: 30,
                last: 29,
                ..
            })
        ));
        assert!(with(4, 7 << 5 | 1).is_ok());
        assert!(with(4, 1).unwrap().day_of_week == 0);
        // Month 1..=12 (four bits reach 15).
        assert!(with(5, 1).is_ok());
        assert!(with(5, 12).is_ok());
        assert_eq!(with(5, 0), Err(TimeError::Month(0)));
        assert_eq!(with(5, 13), Err(TimeError::Month(13)));
        assert_eq!(with(5, 15), Err(TimeError::Month(15)));
        // Year 0..=99 (seven bits reach 127); 2000 is a leap year, 2099 not.
        assert!(with(6, 0).is_ok());
        assert!(matches!(with(6, 99), Err(TimeError::Day { day: 29, .. })));
        let mut late = ok;
        late[4] = 28;
        late[6] = 99;
        assert_eq!(Cp56Time2a::decode(&late).unwrap().year, 99);
        assert_eq!(with(6, 100), Err(TimeError::Year(100)));
        assert_eq!(with(6, 127), Err(TimeError::Year(127)));
        // Day 29 of February only in leap years; 31 only in long months.
        let mut t = sample();
        t.year = 23;
        assert!(t.validate().is_err());
        t.year = 0;
        assert!(t.validate().is_ok());
        t.month = 4;
        t.day = 31;
        assert!(t.validate().is_err());
        t.day = 30;
        assert!(t.validate().is_ok());
        t.month = 12;
        t.day = 31;
        assert!(t.validate().is_ok());
        // A hand-built day of week beyond 7 cannot be encoded.
        t.day_of_week = 8;
        assert_eq!(t.validate(), Err(TimeError::DayOfWeek(8)));
    }

    #[test]
    fn short_input_is_an_error() {
        for n in 0..CP56_LEN {
            assert_eq!(
                Cp56Time2a::decode(&sample().encode()[..n]),
                Err(TimeError::Short(n))
            );
        }
    }

    #[test]
    fn errors_read_well() {
        assert_eq!(
            TimeError::Month(13).to_string(),
            "CP56Time2a month 13 out of range 1..=12"
        );
    }
}
