/* A minimal driver of gpf_bot_axi (README, "Using the IP"): a soft reset, the GRNG's seed, N,
 * the init, then steps. The streams move through the user's DMA: dma_send and dma_recv are
 * the user's, declared here only. Build against the generated header:
 *   cc -I build/bot/rtl -c sw/gpf_bot_driver.c
 * For gpf_uav_axi, the same with gpf_uav_regs.h and GPF_UAV_REGS__ names. */
#include <stddef.h>
#include <stdint.h>
#include "gpf_bot_regs.h"

typedef volatile gpf_bot_regs_t gpf_regs;

/* One SplitMix64 step: the model's seed expansion (gpf.model.grng.seed_words). */
uint64_t gpf_splitmix64(uint64_t *state) {
    uint64_t z = (*state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

/* The seed load: SEED_WORDS words, each written low half first (the high half sends it). */
void gpf_load_seed(gpf_regs *r, uint64_t seed) {
    uint32_t words = r->seed_words & GPF_BOT_REGS__SEED_WORDS__COUNT_bm;
    for (uint32_t i = 0; i < words; i++) {
        uint64_t w = gpf_splitmix64(&seed);
        r->seed_lo = (uint32_t)w;
        r->seed_hi = (uint32_t)(w >> 32);
    }
}

void dma_send(int stream, const void *beat, size_t bytes);   /* the user's */
void dma_recv(int stream, void *beat, size_t bytes);
void wait_irq(void);
enum { S_INIT, S_STEP, M_EST };

/* Init and run `steps` steps: init_beat is 73 bytes ({Sigma0, mu0, N ignored}), each step's
 * input 7 bytes ({z, ox, oy}), each result 107 bytes ({mu, Sigma, L, flags, cycles, ESS}). */
void gpf_run(gpf_regs *r, uint64_t seed, uint32_t particles, const uint8_t *init_beat,
             const uint8_t (*step_in)[7], uint8_t (*est)[107], int steps) {
    r->ctrl = GPF_BOT_REGS__CTRL__SOFT_RESET_bm;          /* a clean filter; RUN low */
    gpf_load_seed(r, seed);
    r->particles = particles;
    dma_send(S_INIT, init_beat, 73);
    r->int_enable = GPF_BOT_REGS__INT_ENABLE__STEP_DONE_bm;
    r->ctrl = GPF_BOT_REGS__CTRL__RUN_bm;                 /* start */
    for (int k = 0; k < steps; k++) {
        dma_send(S_STEP, step_in[k], 7);
        dma_recv(M_EST, est[k], 107);
        wait_irq();
        r->int_status = GPF_BOT_REGS__INT_STATUS__STEP_DONE_bm;   /* write 1 to clear */
    }
}

#ifdef GPF_DRIVER_SELFTEST
/* The seed words of `seed` (tests/test_driver.py compares them with the model's); no DMA. */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
void dma_send(int stream, const void *beat, size_t bytes) { (void)stream; (void)beat; (void)bytes; abort(); }
void dma_recv(int stream, void *beat, size_t bytes) { (void)stream; (void)beat; (void)bytes; abort(); }
void wait_irq(void) { abort(); }

int main(int argc, char **argv) {
    if (argc != 3) return 2;
    uint64_t state = strtoull(argv[1], NULL, 0);
    for (int i = 0; i < atoi(argv[2]); i++)
        printf("%" PRIu64 "\n", gpf_splitmix64(&state));
    return 0;
}
#endif
