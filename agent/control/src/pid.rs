//! TCP's PID controller: the integral is the mean of a fixed window of past errors (pre-filled
//! with zeros) and the derivative is the difference of the last two errors.

use std::collections::VecDeque;

/// A PID controller whose integral term is the mean error over a fixed window.
#[derive(Debug, Clone)]
pub struct Pid {
    kp: f32,
    ki: f32,
    kd: f32,
    window: VecDeque<f32>,
}

impl Pid {
    /// Gains `kp`, `ki`, `kd` and an error window of `window` ticks (at least 2), zero-filled.
    pub fn new(kp: f32, ki: f32, kd: f32, window: usize) -> Self {
        Self {
            kp,
            ki,
            kd,
            window: std::iter::repeat_n(0.0, window.max(2)).collect(),
        }
    }

    /// Adds `error` to the window and returns the controller output.
    pub fn step(&mut self, error: f32) -> f32 {
        self.window.pop_front();
        self.window.push_back(error);
        let integral = self.window.iter().sum::<f32>() / self.window.len() as f32;
        let derivative = error - self.window[self.window.len() - 2];
        self.kp * error + self.ki * integral + self.kd * derivative
    }
}
