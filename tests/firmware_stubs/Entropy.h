/* Declaration-only stand-in for Teensyduino's Entropy library (TRNG on the Teensy 4); see Arduino.h. */
#pragma once
#include <stdint.h>
class EntropyClass {
public:
    void Initialize();
    uint32_t random();
};
extern EntropyClass Entropy;
