// Recording panel.
export function mountRecording(studio) {}
