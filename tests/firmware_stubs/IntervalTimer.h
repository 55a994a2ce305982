/* Declaration-only stand-in for Teensyduino's IntervalTimer (a periodic interrupt timer); see Arduino.h. */
#pragma once
class IntervalTimer {
public:
    bool begin(void (*funct)(), float microseconds);
    void priority(unsigned char n);
    void end();
};
