//! A small ArduPilot DataFlash writer for tests and fuzz seeds: `FMT`
//! messages and messages of those layouts from numeric values (the
//! inverse of [`crate::dataflash::MessageFormat::value`]).

use crate::dataflash::{FMT_TYPE, HEAD, field_size};

/// The layouts of ArduCopter 3.2/3.3 (2014) the converter reads, as in
/// the shared 16.BIN's `FMT` messages: (type, name, format, labels).
pub const LAYOUT_2014: [(u8, &str, &str, &str); 5] = [
    (
        131,
        "IMU",
        "Iffffff",
        "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ",
    ),
    (
        130,
        "GPS",
        "BIHBcLLeeEefI",
        "Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs,VZ,T",
    ),
    (153, "UBX3", "IBfff", "TimeMS,Instance,hAcc,vAcc,sAcc"),
    (
        140,
        "EKF1",
        "IccCffffffccc",
        "TimeMS,Roll,Pitch,Yaw,VN,VE,VD,PN,PE,PD,GX,GY,GZ",
    ),
    (138, "AHR2", "IccCfLL", "TimeMS,Roll,Pitch,Yaw,Alt,Lat,Lng"),
];

/// Current layouts (ArduPilot `libraries/AP_GPS/LogStructure.h`, IMU with
/// an instance field, EKF3 `XKF1`).
pub const LAYOUT_CURRENT: [(u8, &str, &str, &str); 5] = [
    (
        64,
        "IMU",
        "QBffffffIIfBBHH",
        "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz",
    ),
    (
        65,
        "GPS",
        "QBBIHBcLLeffffB",
        "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,Yaw,U",
    ),
    (
        66,
        "GPA",
        "QBCCCCfBIHeHH",
        "TimeUS,I,VDop,HAcc,VAcc,SAcc,YAcc,VV,SMS,Delta,AEl,RTCMFU,RTCMFD",
    ),
    (
        67,
        "XKF1",
        "QBccCfffffffccce",
        "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,GX,GY,GZ,OH",
    ),
    (
        68,
        "AHR2",
        "QccCfLLffff",
        "TimeUS,Roll,Pitch,Yaw,Alt,Lat,Lng,Q1,Q2,Q3,Q4",
    ),
];

/// A DataFlash log being written.
#[derive(Default)]
pub struct DataFlashWriter {
    pub bytes: Vec<u8>,
    layouts: Vec<(u8, String, String)>,
}

fn padded(s: &str, n: usize) -> Vec<u8> {
    let mut b = s.as_bytes().to_vec();
    b.resize(n, 0);
    b
}

impl DataFlashWriter {
    /// A log that starts with the FMT of FMT, as ArduPilot writes it.
    pub fn new() -> Self {
        let mut w = DataFlashWriter::default();
        w.fmt(FMT_TYPE, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns");
        w
    }

    /// A writer with the `FMT` messages of `layouts`.
    pub fn with_layouts(layouts: &[(u8, &str, &str, &str)]) -> Self {
        let mut w = Self::new();
        for (t, n, f, l) in layouts {
            w.fmt(*t, n, f, l);
        }
        w
    }

    /// Writes the `FMT` message of a layout.
    pub fn fmt(&mut self, type_id: u8, name: &str, format: &str, labels: &str) {
        let len = 3 + format
            .bytes()
            .map(|c| field_size(c).expect("format character"))
            .sum::<usize>();
        self.bytes.extend_from_slice(&HEAD);
        self.bytes.push(FMT_TYPE);
        self.bytes.push(type_id);
        self.bytes.push(len as u8);
        self.bytes.extend(padded(name, 4));
        self.bytes.extend(padded(format, 16));
        self.bytes.extend(padded(labels, 64));
        self.layouts
            .push((type_id, name.to_string(), format.to_string()));
    }

    /// Writes a message of layout `name`, one value per field in the log's
    /// units (`c C e E` ×100 and `L` ×1e7 are applied here); missing
    /// values are 0.
    pub fn msg(&mut self, name: &str, values: &[f64]) {
        let (t, _, format) = self
            .layouts
            .iter()
            .find(|l| l.1 == name)
            .expect("layout written")
            .clone();
        self.bytes.extend_from_slice(&HEAD);
        self.bytes.push(t);
        for (k, c) in format.bytes().enumerate() {
            let v = values.get(k).copied().unwrap_or(0.0);
            let b = &mut self.bytes;
            match c {
                b'b' => b.push(v as i8 as u8),
                b'B' | b'M' => b.push(v as u8),
                b'h' => b.extend((v as i16).to_le_bytes()),
                b'H' => b.extend((v as u16).to_le_bytes()),
                b'c' => b.extend(((v * 100.0).round() as i16).to_le_bytes()),
                b'C' => b.extend(((v * 100.0).round() as u16).to_le_bytes()),
                b'i' => b.extend((v as i32).to_le_bytes()),
                b'I' => b.extend((v as u32).to_le_bytes()),
                b'e' => b.extend(((v * 100.0).round() as i32).to_le_bytes()),
                b'E' => b.extend(((v * 100.0).round() as u32).to_le_bytes()),
                b'L' => b.extend(((v * 1e7).round() as i32).to_le_bytes()),
                b'f' => b.extend((v as f32).to_le_bytes()),
                b'd' => b.extend(v.to_le_bytes()),
                b'q' => b.extend((v as i64).to_le_bytes()),
                b'Q' => b.extend((v as u64).to_le_bytes()),
                c => b.extend(std::iter::repeat_n(0u8, field_size(c).unwrap_or(0))),
            }
        }
    }
}
