// Spectrum panel (drawn in spectrum.js once the service sends spectra).
export function mountSpectrum(studio) {}
