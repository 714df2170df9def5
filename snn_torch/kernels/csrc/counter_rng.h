/* Counter-based random numbers, the C side of snn_torch.functional.counter_rng (evolution.rng's
   streams): draw m of a stream with key k is uniform01(k, m), splitmix64's finaliser of the key
   and the counter, so any draw is computed alone, in any order, with the same bits as torch. */
#ifndef SNN_NEAT_COUNTER_RNG_H
#define SNN_NEAT_COUNTER_RNG_H

#include <math.h>
#include <stdint.h>

static inline uint64_t mix64(uint64_t x) {
    x += 0x9E3779B97F4A7C15ULL;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
    return x ^ (x >> 31);
}
/* The top 53 bits of draw `counter`, as an integer X: uniform01 is X 2^-53. */
static inline int64_t uniform01_bits(uint64_t key, uint64_t counter) {
    return (int64_t)(mix64(key ^ mix64(counter)) >> 11);
}
/* Uniform in [0, 1) from the top 53 bits (below 2^53, so the signed conversion is exact). */
static inline double uniform01(uint64_t key, uint64_t counter) {
    return (double)uniform01_bits(key, counter) * 0x1.0p-53;
}
/* The integer T with uniform01(k, m) < p exactly when uniform01_bits(k, m) < T: X 2^-53 < p
   holds for a whole X exactly when X < ceil(p 2^53) (a power-of-two scaling, exact); p NaN or
   at most 0 never holds, p above 1 always. */
static inline int64_t uniform01_threshold(double p) {
    if (!(p > 0)) return 0;
    if (p >= 1) return (int64_t)1 << 53;
    return (int64_t)ceil(p * 0x1.0p53);
}

#endif
