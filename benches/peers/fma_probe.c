// The machine's FP64 limit, measured (BENCHMARKS.md, "The FMA limit"): the
// clock from dependent integer chains, and how many independent FMA (zmm,
// ymm) and add/mul (zmm) instructions a core retires per second. Each probe
// runs 40 times; take the best of each (other processes lower the rest).
// x86-64 with AVX-512F only.
//
//   gcc -O2 -mavx512f -mfma benches/peers/fma_probe.c -o /tmp/fma_probe
//   /tmp/fma_probe 1000000 | sort -k1,1 -k2,2nr     # one core
//   /tmp/fma_probe 1000000 & /tmp/fma_probe 1000000  # both cores at once
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
static double now(void){struct timespec t;clock_gettime(CLOCK_MONOTONIC,&t);return t.tv_sec+t.tv_nsec*1e-9;}
int main(int argc,char**argv){
  long reps = argc>1? atol(argv[1]) : 20000000;
  // clock: 100 dependent adds per iteration
  for (int k=0;k<40;k++){
    long n=reps; long x=0; double t0=now();
    __asm__ volatile("1:\n\t .rept 100\n\t add $1, %0\n\t .endr\n\t dec %1\n\t jnz 1b":"+r"(x),"+r"(n)::"cc");
    double dt=now()-t0; printf("clock: %.3f GHz (dependent adds)\n", reps*100.0/dt/1e9);
  }
  for (int k=0;k<40;k++){
    long n=reps; long x=1; double t0=now();
    __asm__ volatile("1:\n\t .rept 100\n\t imul %0, %0\n\t .endr\n\t dec %1\n\t jnz 1b":"+r"(x),"+r"(n)::"cc");
    double dt=now()-t0; printf("imulclock: %.3f GHz (dependent imul, 3 cycles)\n", reps*300.0/dt/1e9);
  }
  // zmm FMA: 12 independent accumulators, 12 FMAs per iteration
  for (int k=0;k<40;k++){
    long n=reps; double t0=now();
    __asm__ volatile(
      "vxorpd %%zmm0,%%zmm0,%%zmm0\n\t"
      ".irp r,1,2,3,4,5,6,7,8,9,10,11,12\n\t vmovapd %%zmm0,%%zmm\\r\n\t .endr\n\t"
      "1:\n\t"
      ".irp r,1,2,3,4,5,6,7,8,9,10,11,12\n\t vfmadd231pd %%zmm13,%%zmm14,%%zmm\\r\n\t .endr\n\t"
      "dec %0\n\t jnz 1b" : "+r"(n) :: "cc","xmm0","xmm1","xmm2","xmm3","xmm4","xmm5","xmm6","xmm7","xmm8","xmm9","xmm10","xmm11","xmm12","xmm13","xmm14");
    double dt=now()-t0; printf("zmm FMA: %.3f G FMA instr/s\n", reps*12.0/dt/1e9);
  }
  for (int k=0;k<40;k++){
    long n=reps; double t0=now();
    __asm__ volatile(
      "vxorpd %%ymm0,%%ymm0,%%ymm0\n\t"
      ".irp r,1,2,3,4,5,6,7,8,9,10,11,12\n\t vmovapd %%ymm0,%%ymm\\r\n\t .endr\n\t"
      "1:\n\t"
      ".irp r,1,2,3,4,5,6,7,8,9,10,11,12\n\t vfmadd231pd %%ymm13,%%ymm14,%%ymm\\r\n\t .endr\n\t"
      "dec %0\n\t jnz 1b" : "+r"(n) :: "cc","xmm0","xmm1","xmm2","xmm3","xmm4","xmm5","xmm6","xmm7","xmm8","xmm9","xmm10","xmm11","xmm12","xmm13","xmm14");
    double dt=now()-t0; printf("ymm FMA: %.3f G FMA instr/s\n", reps*12.0/dt/1e9);
  }
  // zmm add + mul mix (non-FMA peak): 6 adds + 6 muls independent
  for (int k=0;k<40;k++){
    long n=reps; double t0=now();
    __asm__ volatile(
      "vxorpd %%zmm0,%%zmm0,%%zmm0\n\t"
      ".irp r,1,2,3,4,5,6,7,8,9,10,11,12\n\t vmovapd %%zmm0,%%zmm\\r\n\t .endr\n\t"
      "1:\n\t"
      ".irp r,1,2,3,4,5,6\n\t vaddpd %%zmm13,%%zmm\\r,%%zmm\\r\n\t .endr\n\t"
      ".irp r,7,8,9,10,11,12\n\t vmulpd %%zmm13,%%zmm\\r,%%zmm\\r\n\t .endr\n\t"
      "dec %0\n\t jnz 1b" : "+r"(n) :: "cc","xmm0","xmm1","xmm2","xmm3","xmm4","xmm5","xmm6","xmm7","xmm8","xmm9","xmm10","xmm11","xmm12","xmm13","xmm14");
    double dt=now()-t0; printf("zmm add+mul: %.3f G instr/s\n", reps*12.0/dt/1e9);
  }
  return 0;
}
