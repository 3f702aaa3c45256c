//! PX4 ULog files for tests: a writer of the messages PX4's logger writes
//! (PX4 User Guide, "ULog File Format") and the format definitions of the
//! topics navsync reads, as PX4 v1.13 and v1.14 define them (uORB
//! messages, fields ordered by size with `_padding` as PX4's generator
//! emits them). Independent of the reader under test: the struct encoder
//! here parses the definition strings itself. Feature `test-bags`.

use std::collections::HashMap;

/// `sensor_combined` (PX4 v1.13 msg/SensorCombined.msg).
pub const SENSOR_COMBINED: &str = "sensor_combined:uint64_t timestamp;float[3] gyro_rad;\
uint32_t gyro_integral_dt;int32_t accelerometer_timestamp_relative;float[3] accelerometer_m_s2;\
uint32_t accelerometer_integral_dt;uint8_t accelerometer_clipping;uint8_t gyro_clipping;\
uint8_t accel_calibration_count;uint8_t gyro_calibration_count;";

/// `vehicle_gps_position` (PX4 v1.13): lat/lon int32 1e-7 deg, alt mm;
/// trailing padding (not logged).
pub const VEHICLE_GPS_POSITION: &str = "vehicle_gps_position:uint64_t timestamp;\
uint64_t time_utc_usec;int32_t lat;int32_t lon;int32_t alt;int32_t alt_ellipsoid;\
float s_variance_m_s;float c_variance_rad;float eph;float epv;float hdop;float vdop;\
int32_t noise_per_ms;int32_t jamming_indicator;float vel_m_s;float vel_n_m_s;float vel_e_m_s;\
float vel_d_m_s;float cog_rad;int32_t timestamp_time_relative;float heading;\
float heading_offset;float heading_accuracy;uint32_t device_id;uint16_t automatic_gain_control;\
uint8_t fix_type;uint8_t jamming_state;bool vel_ned_valid;uint8_t satellites_used;\
uint8_t[6] _padding0;";

/// `sensor_gps` (PX4 v1.14): doubles in degrees and metres.
pub const SENSOR_GPS: &str = "sensor_gps:uint64_t timestamp;uint64_t timestamp_sample;\
double latitude_deg;double longitude_deg;double altitude_msl_m;double altitude_ellipsoid_m;\
uint64_t time_utc_usec;uint32_t device_id;float s_variance_m_s;float c_variance_rad;float eph;\
float epv;float hdop;float vdop;int32_t noise_per_ms;int32_t jamming_indicator;float vel_m_s;\
float vel_n_m_s;float vel_e_m_s;float vel_d_m_s;float cog_rad;int32_t timestamp_time_relative;\
float heading;float heading_offset;float heading_accuracy;float rtcm_injection_rate;\
uint16_t automatic_gain_control;uint8_t fix_type;uint8_t jamming_state;\
uint8_t selected_rtcm_instance;bool vel_ned_valid;uint8_t satellites_used;uint8_t[1] _padding0;";

/// `vehicle_attitude` (PX4 v1.13).
pub const VEHICLE_ATTITUDE: &str = "vehicle_attitude:uint64_t timestamp;\
uint64_t timestamp_sample;float[4] q;float[4] delta_q_reset;uint8_t quat_reset_counter;\
uint8_t[7] _padding0;";

/// `vehicle_global_position` (PX4 v1.13).
pub const VEHICLE_GLOBAL_POSITION: &str = "vehicle_global_position:uint64_t timestamp;\
uint64_t timestamp_sample;double lat;double lon;float alt;float alt_ellipsoid;float delta_alt;\
float eph;float epv;float terrain_alt;uint8_t lat_lon_reset_counter;uint8_t alt_reset_counter;\
bool terrain_alt_valid;bool dead_reckoning;uint8_t[4] _padding0;";

/// `vehicle_local_position` (PX4 v1.13, the fields up to the velocity
/// and a few after).
pub const VEHICLE_LOCAL_POSITION: &str = "vehicle_local_position:uint64_t timestamp;\
uint64_t timestamp_sample;float x;float y;float z;float vx;float vy;float vz;float z_deriv;\
float ax;float ay;float az;float heading;bool xy_valid;bool z_valid;bool v_xy_valid;\
bool v_z_valid;uint8_t[4] _padding0;";

/// A nested topic (PX4 `esc_status` with `esc_report[8] esc`), read by
/// navsync only to count it: its layout must resolve.
pub const ESC_REPORT: &str = "esc_report:uint64_t timestamp;float esc_voltage;float esc_current;\
int32_t esc_rpm;uint8_t esc_address;uint8_t esc_state;uint8_t[2] _padding0;";
pub const ESC_STATUS: &str = "esc_status:uint64_t timestamp;uint16_t counter;uint8_t esc_count;\
uint8_t esc_connectiontype;uint8_t[4] _padding0;esc_report[8] esc;";

/// A ULog being written: header, then messages ([ULog] "Data Section").
pub struct UlogWriter {
    pub buf: Vec<u8>,
    defs: HashMap<String, Vec<(String, usize, String)>>,
}

fn base_size(t: &str) -> Option<usize> {
    Some(match t {
        "int8_t" | "uint8_t" | "bool" | "char" => 1,
        "int16_t" | "uint16_t" => 2,
        "int32_t" | "uint32_t" | "float" => 4,
        "int64_t" | "uint64_t" | "double" => 8,
        _ => return None,
    })
}

impl UlogWriter {
    /// Header (magic, version 1, start time) and the flag bits message.
    pub fn new(start_us: u64) -> Self {
        let mut buf = b"ULog\x01\x12\x35\x01".to_vec();
        buf.extend(start_us.to_le_bytes());
        let mut w = UlogWriter {
            buf,
            defs: HashMap::new(),
        };
        // 'B': compat[8], incompat[8], appended offsets[3].
        w.msg(b'B', &[0u8; 40]);
        w
    }

    pub fn msg(&mut self, ty: u8, body: &[u8]) {
        self.buf
            .extend((body.len() as u16).to_le_bytes().iter().chain(&[ty]));
        self.buf.extend(body);
    }

    /// 'F': a format definition.
    pub fn format(&mut self, def: &str) {
        let (name, rest) = def.split_once(':').expect("name:fields");
        let fields = rest
            .split(';')
            .filter(|f| !f.is_empty())
            .map(|f| {
                let (ty, n) = f.split_once(' ').expect("type name");
                let (ty, count) = match ty.split_once('[') {
                    Some((t, c)) => (t, c.trim_end_matches(']').parse().expect("count")),
                    None => (ty, 1),
                };
                (ty.to_string(), count, n.to_string())
            })
            .collect();
        self.defs.insert(name.to_string(), fields);
        self.msg(b'F', def.as_bytes());
    }

    /// 'I': `char[n] key` info.
    pub fn info(&mut self, key: &str, value: &str) {
        let k = format!("char[{}] {key}", value.len());
        let mut b = vec![k.len() as u8];
        b.extend(k.as_bytes());
        b.extend(value.as_bytes());
        self.msg(b'I', &b);
    }

    /// 'P': an int32 parameter.
    pub fn param_i32(&mut self, name: &str, v: i32) {
        let k = format!("int32_t {name}");
        let mut b = vec![k.len() as u8];
        b.extend(k.as_bytes());
        b.extend(v.to_le_bytes());
        self.msg(b'P', &b);
    }

    /// 'A': subscribes `name` instance `multi_id` as `msg_id`.
    pub fn add(&mut self, multi_id: u8, msg_id: u16, name: &str) {
        let mut b = vec![multi_id];
        b.extend(msg_id.to_le_bytes());
        b.extend(name.as_bytes());
        self.msg(b'A', &b);
    }

    /// 'D': one struct of `topic`, each field from `value(name, index)`
    /// (nested fields as `outer[i].inner`), trailing padding left out as
    /// PX4's logger does.
    pub fn data(&mut self, msg_id: u16, topic: &str, value: &dyn Fn(&str, usize) -> f64) {
        let mut b = msg_id.to_le_bytes().to_vec();
        self.encode(topic, "", value, &mut b);
        let fields = &self.defs[topic];
        if let Some((t, n, name)) = fields.last()
            && name.starts_with("_padding")
        {
            b.truncate(b.len() - base_size(t).unwrap_or(1) * n);
        }
        self.msg(b'D', &b);
    }

    fn encode(
        &self,
        topic: &str,
        prefix: &str,
        value: &dyn Fn(&str, usize) -> f64,
        b: &mut Vec<u8>,
    ) {
        for (ty, n, name) in &self.defs[topic] {
            let full = format!("{prefix}{name}");
            if base_size(ty).is_none() {
                for i in 0..*n {
                    self.encode(ty, &format!("{full}[{i}]."), value, b);
                }
                continue;
            }
            for i in 0..*n {
                let v = if name.starts_with("_padding") {
                    0.0
                } else {
                    value(&full, i)
                };
                match ty.as_str() {
                    "int8_t" => b.push(v as i8 as u8),
                    "uint8_t" | "bool" | "char" => b.push(v as u8),
                    "int16_t" => b.extend((v as i16).to_le_bytes()),
                    "uint16_t" => b.extend((v as u16).to_le_bytes()),
                    "int32_t" => b.extend((v.round() as i32).to_le_bytes()),
                    "uint32_t" => b.extend((v as u32).to_le_bytes()),
                    "int64_t" => b.extend((v as i64).to_le_bytes()),
                    "uint64_t" => b.extend((v as u64).to_le_bytes()),
                    "float" => b.extend((v as f32).to_le_bytes()),
                    _ => b.extend(v.to_le_bytes()),
                }
            }
        }
    }

    /// 'D' with an exact u64 timestamp first (f64 values lose µs beyond 2^53).
    pub fn data_at(
        &mut self,
        msg_id: u16,
        topic: &str,
        t_us: u64,
        value: &dyn Fn(&str, usize) -> f64,
    ) {
        let start = self.buf.len();
        self.data(msg_id, topic, value);
        // Header (3) + msg_id (2): the timestamp field follows.
        self.buf[start + 5..start + 13].copy_from_slice(&t_us.to_le_bytes());
    }

    /// 'S': synchronization message.
    pub fn sync(&mut self) {
        self.msg(b'S', &crate::ulog::SYNC_MAGIC);
    }

    /// 'O': a dropout of `ms`.
    pub fn dropout(&mut self, ms: u16) {
        self.msg(b'O', &ms.to_le_bytes());
    }

    /// 'L': a logged string.
    pub fn log(&mut self, level: u8, t_us: u64, text: &str) {
        let mut b = vec![level];
        b.extend(t_us.to_le_bytes());
        b.extend(text.as_bytes());
        self.msg(b'L', &b);
    }
}
