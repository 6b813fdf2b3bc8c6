// Presets panel.
export function mountPresets(studio) {}
