/* Preloaded into the sanitizer test runs (scripts/sanitize.sh, fuzz.sh):
 * dlclose() keeps every shared object loaded until the process exits.
 *
 * Why: Mesa unloads its driver (swrast_dri.so, llvmpipe) when the display
 * closes, while allocations it made are still referenced from that driver's
 * own data. LeakSanitizer, running at exit, no longer sees those
 * references and reports the driver's live memory as leaks from an
 * "<unknown module>", which no suppression can name. Kept loaded, the
 * references are visible and nothing is reported; a real leak anywhere is
 * still reported, now with a symbolised stack. Plain C, no sanitizer: it is
 * also loaded into the shells and tools the tests start. */
int dlclose(void *handle) {
  (void)handle;
  return 0;
}
