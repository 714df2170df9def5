/* Whole episodes in one native call (see episodes.h). The controllers' arithmetic is the C
   kernels' (recurrent_izhikevich.c's lane functions, the sigmoid kernel's ordered sums), the
   decoders' and the rollout's are the torch modules' operations in their order, sigmoid from
   portable_math.h: built with -ffp-contract=off, a row's returns and steps are the torch
   rollout's bits (tests/evolution/test_native_episodes.py).

   Each thread keeps up to LANES rows in flight. Every control step it observes their plants,
   runs their controllers side by side (the spiking networks in lanes, as the network kernel
   does), steps their plants in one call, and retires the rows that finished, taking the next
   row of the batch in their place: finished rows cost nothing and no thread waits for another
   until the last row is done. A row's arithmetic is its own, so its result does not depend on
   its lane, its thread or the thread count. */
#include "episodes.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "native_plant.h"
#include "portable_math.h"
/* the network kernels' lane functions, size dispatch, decoders and sigmoid row update; their
   exported functions stay hidden here */
#pragma GCC visibility push(hidden)
#include "recurrent_izhikevich.c"
#include "recurrent_sigmoid.c"
#pragma GCC visibility pop

#define PASTE_(x, y) x##y
#define PASTE(x, y) PASTE_(x, y)

#define T float
#define SFX f32
#include "episodes_impl.h"
#undef T
#undef SFX

#define T double
#define SFX f64
#include "episodes_impl.h"
#undef T
#undef SFX
