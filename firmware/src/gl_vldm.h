/**
 * @file gl_vldm.h
 * @brief Multi-register loads for the unrolled step (gl_step.h). GL_LDk(p, a0..) loads k consecutive
 *        floats into new locals: coefficient chunks in registers s16..s31; GL_LDSk does the same for the
 *        state in registers s8..s15, where it stays for the whole step. On the Cortex-M4F each is one
 *        `vldmia` instead of k `vldr`; elsewhere plain loads. The values are the same on every target.
 */
#ifndef GAINLINK_GL_VLDM_H
#define GAINLINK_GL_VLDM_H

#if defined(__arm__) && defined(__ARM_FP) && ((__ARM_FP) & 4) && !defined(GL_NO_VLDM)
#define GL_HAVE_VLDM 1
#else
#define GL_HAVE_VLDM 0
#endif

#define GL_LD1(p, a0) const float a0 = (p)[0]
#define GL_LDS1(p, a0) const float a0 = (p)[0]

#if GL_HAVE_VLDM
#define GL_LD2(p, a0, a1) \
    float a0, a1; \
    do { \
        register float gl_t0 __asm__("s16"); register float gl_t1 __asm__("s17"); \
        __asm__("vldmia %[src], {s16-s17}" \
                : "=t"(gl_t0), "=t"(gl_t1) \
                : [src] "r"(p), "m"(*(const float(*)[2])(p))); \
        a0 = gl_t0; a1 = gl_t1; \
    } while (0)
#else
#define GL_LD2(p, a0, a1) const float a0 = (p)[0], a1 = (p)[1]
#endif

#if GL_HAVE_VLDM
#define GL_LD3(p, a0, a1, a2) \
    float a0, a1, a2; \
    do { \
        register float gl_t0 __asm__("s16"); register float gl_t1 __asm__("s17"); register float gl_t2 __asm__("s18"); \
        __asm__("vldmia %[src], {s16-s18}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2) \
                : [src] "r"(p), "m"(*(const float(*)[3])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; \
    } while (0)
#else
#define GL_LD3(p, a0, a1, a2) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2]
#endif

#if GL_HAVE_VLDM
#define GL_LD4(p, a0, a1, a2, a3) \
    float a0, a1, a2, a3; \
    do { \
        register float gl_t0 __asm__("s16"); register float gl_t1 __asm__("s17"); register float gl_t2 __asm__("s18"); register float gl_t3 __asm__("s19"); \
        __asm__("vldmia %[src], {s16-s19}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3) \
                : [src] "r"(p), "m"(*(const float(*)[4])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; \
    } while (0)
#else
#define GL_LD4(p, a0, a1, a2, a3) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3]
#endif

#if GL_HAVE_VLDM
#define GL_LD5(p, a0, a1, a2, a3, a4) \
    float a0, a1, a2, a3, a4; \
    do { \
        register float gl_t0 __asm__("s16"); register float gl_t1 __asm__("s17"); register float gl_t2 __asm__("s18"); register float gl_t3 __asm__("s19"); register float gl_t4 __asm__("s20"); \
        __asm__("vldmia %[src], {s16-s20}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3), "=t"(gl_t4) \
                : [src] "r"(p), "m"(*(const float(*)[5])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; a4 = gl_t4; \
    } while (0)
#else
#define GL_LD5(p, a0, a1, a2, a3, a4) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3], a4 = (p)[4]
#endif

#if GL_HAVE_VLDM
#define GL_LD6(p, a0, a1, a2, a3, a4, a5) \
    float a0, a1, a2, a3, a4, a5; \
    do { \
        register float gl_t0 __asm__("s16"); register float gl_t1 __asm__("s17"); register float gl_t2 __asm__("s18"); register float gl_t3 __asm__("s19"); register float gl_t4 __asm__("s20"); register float gl_t5 __asm__("s21"); \
        __asm__("vldmia %[src], {s16-s21}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3), "=t"(gl_t4), "=t"(gl_t5) \
                : [src] "r"(p), "m"(*(const float(*)[6])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; a4 = gl_t4; a5 = gl_t5; \
    } while (0)
#else
#define GL_LD6(p, a0, a1, a2, a3, a4, a5) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3], a4 = (p)[4], a5 = (p)[5]
#endif

#if GL_HAVE_VLDM
#define GL_LD7(p, a0, a1, a2, a3, a4, a5, a6) \
    float a0, a1, a2, a3, a4, a5, a6; \
    do { \
        register float gl_t0 __asm__("s16"); register float gl_t1 __asm__("s17"); register float gl_t2 __asm__("s18"); register float gl_t3 __asm__("s19"); register float gl_t4 __asm__("s20"); register float gl_t5 __asm__("s21"); register float gl_t6 __asm__("s22"); \
        __asm__("vldmia %[src], {s16-s22}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3), "=t"(gl_t4), "=t"(gl_t5), "=t"(gl_t6) \
                : [src] "r"(p), "m"(*(const float(*)[7])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; a4 = gl_t4; a5 = gl_t5; a6 = gl_t6; \
    } while (0)
#else
#define GL_LD7(p, a0, a1, a2, a3, a4, a5, a6) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3], a4 = (p)[4], a5 = (p)[5], a6 = (p)[6]
#endif

#if GL_HAVE_VLDM
#define GL_LD8(p, a0, a1, a2, a3, a4, a5, a6, a7) \
    float a0, a1, a2, a3, a4, a5, a6, a7; \
    do { \
        register float gl_t0 __asm__("s16"); register float gl_t1 __asm__("s17"); register float gl_t2 __asm__("s18"); register float gl_t3 __asm__("s19"); register float gl_t4 __asm__("s20"); register float gl_t5 __asm__("s21"); register float gl_t6 __asm__("s22"); register float gl_t7 __asm__("s23"); \
        __asm__("vldmia %[src], {s16-s23}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3), "=t"(gl_t4), "=t"(gl_t5), "=t"(gl_t6), "=t"(gl_t7) \
                : [src] "r"(p), "m"(*(const float(*)[8])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; a4 = gl_t4; a5 = gl_t5; a6 = gl_t6; a7 = gl_t7; \
    } while (0)
#else
#define GL_LD8(p, a0, a1, a2, a3, a4, a5, a6, a7) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3], a4 = (p)[4], a5 = (p)[5], a6 = (p)[6], a7 = (p)[7]
#endif

#if GL_HAVE_VLDM
#define GL_LD9(p, a0, a1, a2, a3, a4, a5, a6, a7, a8) \
    float a0, a1, a2, a3, a4, a5, a6, a7, a8; \
    do { \
        register float gl_t0 __asm__("s16"); register float gl_t1 __asm__("s17"); register float gl_t2 __asm__("s18"); register float gl_t3 __asm__("s19"); register float gl_t4 __asm__("s20"); register float gl_t5 __asm__("s21"); register float gl_t6 __asm__("s22"); register float gl_t7 __asm__("s23"); register float gl_t8 __asm__("s24"); \
        __asm__("vldmia %[src], {s16-s24}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3), "=t"(gl_t4), "=t"(gl_t5), "=t"(gl_t6), "=t"(gl_t7), "=t"(gl_t8) \
                : [src] "r"(p), "m"(*(const float(*)[9])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; a4 = gl_t4; a5 = gl_t5; a6 = gl_t6; a7 = gl_t7; a8 = gl_t8; \
    } while (0)
#else
#define GL_LD9(p, a0, a1, a2, a3, a4, a5, a6, a7, a8) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3], a4 = (p)[4], a5 = (p)[5], a6 = (p)[6], a7 = (p)[7], a8 = (p)[8]
#endif

#if GL_HAVE_VLDM
#define GL_LD10(p, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9) \
    float a0, a1, a2, a3, a4, a5, a6, a7, a8, a9; \
    do { \
        register float gl_t0 __asm__("s16"); register float gl_t1 __asm__("s17"); register float gl_t2 __asm__("s18"); register float gl_t3 __asm__("s19"); register float gl_t4 __asm__("s20"); register float gl_t5 __asm__("s21"); register float gl_t6 __asm__("s22"); register float gl_t7 __asm__("s23"); register float gl_t8 __asm__("s24"); register float gl_t9 __asm__("s25"); \
        __asm__("vldmia %[src], {s16-s25}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3), "=t"(gl_t4), "=t"(gl_t5), "=t"(gl_t6), "=t"(gl_t7), "=t"(gl_t8), "=t"(gl_t9) \
                : [src] "r"(p), "m"(*(const float(*)[10])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; a4 = gl_t4; a5 = gl_t5; a6 = gl_t6; a7 = gl_t7; a8 = gl_t8; a9 = gl_t9; \
    } while (0)
#else
#define GL_LD10(p, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3], a4 = (p)[4], a5 = (p)[5], a6 = (p)[6], a7 = (p)[7], a8 = (p)[8], a9 = (p)[9]
#endif

#if GL_HAVE_VLDM
#define GL_LD11(p, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10) \
    float a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10; \
    do { \
        register float gl_t0 __asm__("s16"); register float gl_t1 __asm__("s17"); register float gl_t2 __asm__("s18"); register float gl_t3 __asm__("s19"); register float gl_t4 __asm__("s20"); register float gl_t5 __asm__("s21"); register float gl_t6 __asm__("s22"); register float gl_t7 __asm__("s23"); register float gl_t8 __asm__("s24"); register float gl_t9 __asm__("s25"); register float gl_t10 __asm__("s26"); \
        __asm__("vldmia %[src], {s16-s26}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3), "=t"(gl_t4), "=t"(gl_t5), "=t"(gl_t6), "=t"(gl_t7), "=t"(gl_t8), "=t"(gl_t9), "=t"(gl_t10) \
                : [src] "r"(p), "m"(*(const float(*)[11])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; a4 = gl_t4; a5 = gl_t5; a6 = gl_t6; a7 = gl_t7; a8 = gl_t8; a9 = gl_t9; a10 = gl_t10; \
    } while (0)
#else
#define GL_LD11(p, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3], a4 = (p)[4], a5 = (p)[5], a6 = (p)[6], a7 = (p)[7], a8 = (p)[8], a9 = (p)[9], a10 = (p)[10]
#endif

#if GL_HAVE_VLDM
#define GL_LD12(p, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11) \
    float a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11; \
    do { \
        register float gl_t0 __asm__("s16"); register float gl_t1 __asm__("s17"); register float gl_t2 __asm__("s18"); register float gl_t3 __asm__("s19"); register float gl_t4 __asm__("s20"); register float gl_t5 __asm__("s21"); register float gl_t6 __asm__("s22"); register float gl_t7 __asm__("s23"); register float gl_t8 __asm__("s24"); register float gl_t9 __asm__("s25"); register float gl_t10 __asm__("s26"); register float gl_t11 __asm__("s27"); \
        __asm__("vldmia %[src], {s16-s27}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3), "=t"(gl_t4), "=t"(gl_t5), "=t"(gl_t6), "=t"(gl_t7), "=t"(gl_t8), "=t"(gl_t9), "=t"(gl_t10), "=t"(gl_t11) \
                : [src] "r"(p), "m"(*(const float(*)[12])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; a4 = gl_t4; a5 = gl_t5; a6 = gl_t6; a7 = gl_t7; a8 = gl_t8; a9 = gl_t9; a10 = gl_t10; a11 = gl_t11; \
    } while (0)
#else
#define GL_LD12(p, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3], a4 = (p)[4], a5 = (p)[5], a6 = (p)[6], a7 = (p)[7], a8 = (p)[8], a9 = (p)[9], a10 = (p)[10], a11 = (p)[11]
#endif

#if GL_HAVE_VLDM
#define GL_LD13(p, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12) \
    float a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12; \
    do { \
        register float gl_t0 __asm__("s16"); register float gl_t1 __asm__("s17"); register float gl_t2 __asm__("s18"); register float gl_t3 __asm__("s19"); register float gl_t4 __asm__("s20"); register float gl_t5 __asm__("s21"); register float gl_t6 __asm__("s22"); register float gl_t7 __asm__("s23"); register float gl_t8 __asm__("s24"); register float gl_t9 __asm__("s25"); register float gl_t10 __asm__("s26"); register float gl_t11 __asm__("s27"); register float gl_t12 __asm__("s28"); \
        __asm__("vldmia %[src], {s16-s28}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3), "=t"(gl_t4), "=t"(gl_t5), "=t"(gl_t6), "=t"(gl_t7), "=t"(gl_t8), "=t"(gl_t9), "=t"(gl_t10), "=t"(gl_t11), "=t"(gl_t12) \
                : [src] "r"(p), "m"(*(const float(*)[13])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; a4 = gl_t4; a5 = gl_t5; a6 = gl_t6; a7 = gl_t7; a8 = gl_t8; a9 = gl_t9; a10 = gl_t10; a11 = gl_t11; a12 = gl_t12; \
    } while (0)
#else
#define GL_LD13(p, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3], a4 = (p)[4], a5 = (p)[5], a6 = (p)[6], a7 = (p)[7], a8 = (p)[8], a9 = (p)[9], a10 = (p)[10], a11 = (p)[11], a12 = (p)[12]
#endif

#if GL_HAVE_VLDM
#define GL_LD14(p, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13) \
    float a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13; \
    do { \
        register float gl_t0 __asm__("s16"); register float gl_t1 __asm__("s17"); register float gl_t2 __asm__("s18"); register float gl_t3 __asm__("s19"); register float gl_t4 __asm__("s20"); register float gl_t5 __asm__("s21"); register float gl_t6 __asm__("s22"); register float gl_t7 __asm__("s23"); register float gl_t8 __asm__("s24"); register float gl_t9 __asm__("s25"); register float gl_t10 __asm__("s26"); register float gl_t11 __asm__("s27"); register float gl_t12 __asm__("s28"); register float gl_t13 __asm__("s29"); \
        __asm__("vldmia %[src], {s16-s29}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3), "=t"(gl_t4), "=t"(gl_t5), "=t"(gl_t6), "=t"(gl_t7), "=t"(gl_t8), "=t"(gl_t9), "=t"(gl_t10), "=t"(gl_t11), "=t"(gl_t12), "=t"(gl_t13) \
                : [src] "r"(p), "m"(*(const float(*)[14])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; a4 = gl_t4; a5 = gl_t5; a6 = gl_t6; a7 = gl_t7; a8 = gl_t8; a9 = gl_t9; a10 = gl_t10; a11 = gl_t11; a12 = gl_t12; a13 = gl_t13; \
    } while (0)
#else
#define GL_LD14(p, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3], a4 = (p)[4], a5 = (p)[5], a6 = (p)[6], a7 = (p)[7], a8 = (p)[8], a9 = (p)[9], a10 = (p)[10], a11 = (p)[11], a12 = (p)[12], a13 = (p)[13]
#endif

#if GL_HAVE_VLDM
#define GL_LD15(p, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13, a14) \
    float a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13, a14; \
    do { \
        register float gl_t0 __asm__("s16"); register float gl_t1 __asm__("s17"); register float gl_t2 __asm__("s18"); register float gl_t3 __asm__("s19"); register float gl_t4 __asm__("s20"); register float gl_t5 __asm__("s21"); register float gl_t6 __asm__("s22"); register float gl_t7 __asm__("s23"); register float gl_t8 __asm__("s24"); register float gl_t9 __asm__("s25"); register float gl_t10 __asm__("s26"); register float gl_t11 __asm__("s27"); register float gl_t12 __asm__("s28"); register float gl_t13 __asm__("s29"); register float gl_t14 __asm__("s30"); \
        __asm__("vldmia %[src], {s16-s30}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3), "=t"(gl_t4), "=t"(gl_t5), "=t"(gl_t6), "=t"(gl_t7), "=t"(gl_t8), "=t"(gl_t9), "=t"(gl_t10), "=t"(gl_t11), "=t"(gl_t12), "=t"(gl_t13), "=t"(gl_t14) \
                : [src] "r"(p), "m"(*(const float(*)[15])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; a4 = gl_t4; a5 = gl_t5; a6 = gl_t6; a7 = gl_t7; a8 = gl_t8; a9 = gl_t9; a10 = gl_t10; a11 = gl_t11; a12 = gl_t12; a13 = gl_t13; a14 = gl_t14; \
    } while (0)
#else
#define GL_LD15(p, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13, a14) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3], a4 = (p)[4], a5 = (p)[5], a6 = (p)[6], a7 = (p)[7], a8 = (p)[8], a9 = (p)[9], a10 = (p)[10], a11 = (p)[11], a12 = (p)[12], a13 = (p)[13], a14 = (p)[14]
#endif

#if GL_HAVE_VLDM
#define GL_LD16(p, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13, a14, a15) \
    float a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13, a14, a15; \
    do { \
        register float gl_t0 __asm__("s16"); register float gl_t1 __asm__("s17"); register float gl_t2 __asm__("s18"); register float gl_t3 __asm__("s19"); register float gl_t4 __asm__("s20"); register float gl_t5 __asm__("s21"); register float gl_t6 __asm__("s22"); register float gl_t7 __asm__("s23"); register float gl_t8 __asm__("s24"); register float gl_t9 __asm__("s25"); register float gl_t10 __asm__("s26"); register float gl_t11 __asm__("s27"); register float gl_t12 __asm__("s28"); register float gl_t13 __asm__("s29"); register float gl_t14 __asm__("s30"); register float gl_t15 __asm__("s31"); \
        __asm__("vldmia %[src], {s16-s31}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3), "=t"(gl_t4), "=t"(gl_t5), "=t"(gl_t6), "=t"(gl_t7), "=t"(gl_t8), "=t"(gl_t9), "=t"(gl_t10), "=t"(gl_t11), "=t"(gl_t12), "=t"(gl_t13), "=t"(gl_t14), "=t"(gl_t15) \
                : [src] "r"(p), "m"(*(const float(*)[16])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; a4 = gl_t4; a5 = gl_t5; a6 = gl_t6; a7 = gl_t7; a8 = gl_t8; a9 = gl_t9; a10 = gl_t10; a11 = gl_t11; a12 = gl_t12; a13 = gl_t13; a14 = gl_t14; a15 = gl_t15; \
    } while (0)
#else
#define GL_LD16(p, a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13, a14, a15) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3], a4 = (p)[4], a5 = (p)[5], a6 = (p)[6], a7 = (p)[7], a8 = (p)[8], a9 = (p)[9], a10 = (p)[10], a11 = (p)[11], a12 = (p)[12], a13 = (p)[13], a14 = (p)[14], a15 = (p)[15]
#endif

#if GL_HAVE_VLDM
#define GL_LDS2(p, a0, a1) \
    float a0, a1; \
    do { \
        register float gl_t0 __asm__("s8"); register float gl_t1 __asm__("s9"); \
        __asm__("vldmia %[src], {s8-s9}" \
                : "=t"(gl_t0), "=t"(gl_t1) \
                : [src] "r"(p), "m"(*(const float(*)[2])(p))); \
        a0 = gl_t0; a1 = gl_t1; \
    } while (0)
#else
#define GL_LDS2(p, a0, a1) const float a0 = (p)[0], a1 = (p)[1]
#endif

#if GL_HAVE_VLDM
#define GL_LDS3(p, a0, a1, a2) \
    float a0, a1, a2; \
    do { \
        register float gl_t0 __asm__("s8"); register float gl_t1 __asm__("s9"); register float gl_t2 __asm__("s10"); \
        __asm__("vldmia %[src], {s8-s10}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2) \
                : [src] "r"(p), "m"(*(const float(*)[3])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; \
    } while (0)
#else
#define GL_LDS3(p, a0, a1, a2) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2]
#endif

#if GL_HAVE_VLDM
#define GL_LDS4(p, a0, a1, a2, a3) \
    float a0, a1, a2, a3; \
    do { \
        register float gl_t0 __asm__("s8"); register float gl_t1 __asm__("s9"); register float gl_t2 __asm__("s10"); register float gl_t3 __asm__("s11"); \
        __asm__("vldmia %[src], {s8-s11}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3) \
                : [src] "r"(p), "m"(*(const float(*)[4])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; \
    } while (0)
#else
#define GL_LDS4(p, a0, a1, a2, a3) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3]
#endif

#if GL_HAVE_VLDM
#define GL_LDS5(p, a0, a1, a2, a3, a4) \
    float a0, a1, a2, a3, a4; \
    do { \
        register float gl_t0 __asm__("s8"); register float gl_t1 __asm__("s9"); register float gl_t2 __asm__("s10"); register float gl_t3 __asm__("s11"); register float gl_t4 __asm__("s12"); \
        __asm__("vldmia %[src], {s8-s12}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3), "=t"(gl_t4) \
                : [src] "r"(p), "m"(*(const float(*)[5])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; a4 = gl_t4; \
    } while (0)
#else
#define GL_LDS5(p, a0, a1, a2, a3, a4) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3], a4 = (p)[4]
#endif

#if GL_HAVE_VLDM
#define GL_LDS6(p, a0, a1, a2, a3, a4, a5) \
    float a0, a1, a2, a3, a4, a5; \
    do { \
        register float gl_t0 __asm__("s8"); register float gl_t1 __asm__("s9"); register float gl_t2 __asm__("s10"); register float gl_t3 __asm__("s11"); register float gl_t4 __asm__("s12"); register float gl_t5 __asm__("s13"); \
        __asm__("vldmia %[src], {s8-s13}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3), "=t"(gl_t4), "=t"(gl_t5) \
                : [src] "r"(p), "m"(*(const float(*)[6])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; a4 = gl_t4; a5 = gl_t5; \
    } while (0)
#else
#define GL_LDS6(p, a0, a1, a2, a3, a4, a5) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3], a4 = (p)[4], a5 = (p)[5]
#endif

#if GL_HAVE_VLDM
#define GL_LDS7(p, a0, a1, a2, a3, a4, a5, a6) \
    float a0, a1, a2, a3, a4, a5, a6; \
    do { \
        register float gl_t0 __asm__("s8"); register float gl_t1 __asm__("s9"); register float gl_t2 __asm__("s10"); register float gl_t3 __asm__("s11"); register float gl_t4 __asm__("s12"); register float gl_t5 __asm__("s13"); register float gl_t6 __asm__("s14"); \
        __asm__("vldmia %[src], {s8-s14}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3), "=t"(gl_t4), "=t"(gl_t5), "=t"(gl_t6) \
                : [src] "r"(p), "m"(*(const float(*)[7])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; a4 = gl_t4; a5 = gl_t5; a6 = gl_t6; \
    } while (0)
#else
#define GL_LDS7(p, a0, a1, a2, a3, a4, a5, a6) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3], a4 = (p)[4], a5 = (p)[5], a6 = (p)[6]
#endif

#if GL_HAVE_VLDM
#define GL_LDS8(p, a0, a1, a2, a3, a4, a5, a6, a7) \
    float a0, a1, a2, a3, a4, a5, a6, a7; \
    do { \
        register float gl_t0 __asm__("s8"); register float gl_t1 __asm__("s9"); register float gl_t2 __asm__("s10"); register float gl_t3 __asm__("s11"); register float gl_t4 __asm__("s12"); register float gl_t5 __asm__("s13"); register float gl_t6 __asm__("s14"); register float gl_t7 __asm__("s15"); \
        __asm__("vldmia %[src], {s8-s15}" \
                : "=t"(gl_t0), "=t"(gl_t1), "=t"(gl_t2), "=t"(gl_t3), "=t"(gl_t4), "=t"(gl_t5), "=t"(gl_t6), "=t"(gl_t7) \
                : [src] "r"(p), "m"(*(const float(*)[8])(p))); \
        a0 = gl_t0; a1 = gl_t1; a2 = gl_t2; a3 = gl_t3; a4 = gl_t4; a5 = gl_t5; a6 = gl_t6; a7 = gl_t7; \
    } while (0)
#else
#define GL_LDS8(p, a0, a1, a2, a3, a4, a5, a6, a7) const float a0 = (p)[0], a1 = (p)[1], a2 = (p)[2], a3 = (p)[3], a4 = (p)[4], a5 = (p)[5], a6 = (p)[6], a7 = (p)[7]
#endif

#endif /* GAINLINK_GL_VLDM_H */
