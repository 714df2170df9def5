/* Counter-based random numbers, the C side of snn_torch.functional.counter_rng (evolution.rng's
   streams): draw m of a stream with key k is uniform01(k, m), splitmix64's finaliser of the key
   and the counter, so any draw is computed alone, in any order, with the same bits as torch. */
#ifndef SNN_NEAT_COUNTER_RNG_H
#define SNN_NEAT_COUNTER_RNG_H

#include <stdint.h>

static inline uint64_t mix64(uint64_t x) {
    x += 0x9E3779B97F4A7C15ULL;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
    return x ^ (x >> 31);
}
/* Uniform in [0, 1) from the top 53 bits. */
static inline double uniform01(uint64_t key, uint64_t counter) {
    return (double)(mix64(key ^ mix64(counter)) >> 11) * 0x1.0p-53;
}

#endif
