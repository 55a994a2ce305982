/* A declaration-only stand-in for the Teensyduino core, just enough for the host C++ compiler to check the
 * sketch's syntax and types (tests/test_firmware.py). Nothing here runs; it is not the real core. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#define A0 14
#define A1 15
#define A2 16
extern volatile uint32_t HW_OCOTP_CFG0;
extern volatile uint32_t HW_OCOTP_CFG1;

int analogRead(uint8_t pin);
void analogReadResolution(unsigned int bits);
void analogReadAveraging(unsigned int num);
void noInterrupts();
void interrupts();

class usb_serial_class {
public:
    void begin(long baud);
    size_t write(const uint8_t *buf, size_t len);
    int availableForWrite();
    int dtr();
};
extern usb_serial_class Serial;
